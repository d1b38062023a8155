"""``launch.py study``: error against run time over the fidelity knobs (issue 6).

Each knob is a list of settings (dotted-path overrides of the scenario). Every setting runs in process (the same
participants as a launched run, without process start-up in the timing) for a short duration; its error is
measured against the knob's highest-fidelity setting or an absolute reference (the exact ray cast, the ground-
truth height map), and its cost as wall time per simulated second. The result is a table, a CSV and one plot
per knob of error against run time with the default marked, so a user can pick a point on the curve.
"""
from __future__ import annotations

import csv
import json
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from cosim.scenario.config import Scenario
from cosim.report.figures import DPI, fig_study
from cosim.runtime.inprocess import simulate
from cosim.runtime.progress import run_progress
from cosim.runtime.outputs import clean_json, compose_summary

__all__ = ["Setting", "Knob", "KNOBS", "apply_overrides", "run_setting", "run_study"]

log = logging.getLogger("cosim.studies.study")


@dataclass(frozen=True)
class Setting:
    label: str
    overrides: dict = field(default_factory=dict)


@dataclass
class Result:
    setting: Setting
    summary: dict
    series: dict
    arrays: dict
    wall_per_sim_s: float


@dataclass(frozen=True)
class Knob:
    """A fidelity knob: ``base`` overrides for the whole study, the settings, and how error is measured.

    ``error(result, reference)`` returns the error of one setting; ``reference`` is the result of the setting
    labelled ``reference`` (or ``reference(label)`` when it is a function: the dynamics knob compares each
    setting with Radau at the same step, because the controller is sampled at the step), or None when the
    error is absolute.
    """

    name: str
    error_label: str
    settings: tuple[Setting, ...]
    default: str
    error: Callable[[Result, Result | None], float]
    reference: str | Callable[[str], str] | None = None
    base: dict = field(default_factory=dict)


def apply_overrides(scenario: Scenario, overrides: dict) -> Scenario:
    """A copy of ``scenario`` with dotted-path overrides applied, validated whole."""
    data = scenario.model_dump(mode="json")
    for path, value in overrides.items():
        node = data
        *parents, leaf = path.split(".")
        for p in parents:
            node = node[p]
        if leaf not in node:
            raise KeyError(f"study override {path!r}: no such field")
        node[leaf] = value
    return Scenario.model_validate_json(json.dumps(data))


def run_setting(scenario: Scenario, progress=None) -> tuple[dict, dict, dict, float]:
    """Run in process; return (summary, series, final arrays, wall time per simulated second). ``progress``: a
    per-frame callable (cosim.runtime.progress.run_progress)."""
    t0 = time.perf_counter()
    run = simulate(scenario, progress=progress)
    wall = time.perf_counter() - t0
    summary = compose_summary(scenario, run.recorder, run.ring, wall_time_s=wall, error=None)
    sim = max(scenario.frames * scenario.timing.sensor_period_s, 1e-9)
    return summary, run.recorder.series(), dict(run.recorder.arrays), wall / sim


def _track_error(res: Result, ref: Result | None) -> float:
    """Largest cart position difference from the reference trajectory over the run, m."""
    d = np.hypot(res.series["dyn_state.cart_x_m"] - ref.series["dyn_state.cart_x_m"],
                 res.series["dyn_state.cart_y_m"] - ref.series["dyn_state.cart_y_m"])
    return float(np.max(d))


def _section_error(res: Result, ref: Result | None) -> float:
    """Largest difference of the final section mean heights from the reference, m."""
    a = np.asarray(res.summary["fill"]["section_mean_height_m"], dtype=float)
    b = np.asarray(ref.summary["fill"]["section_mean_height_m"], dtype=float)
    return float(np.max(np.abs(a - b)))


def _range_error(res: Result, ref: Result | None) -> float:
    """Mean LiDAR range error against the exact ray cast of the same scene, m."""
    rng = (res.summary.get("perception") or {}).get("range_error") or {}
    return float(rng.get("mean_m", np.nan))


def _height_rmse(res: Result, ref: Result | None) -> float:
    """RMSE of the perceived height map against the ground truth, m."""
    return float((res.summary.get("perception") or {}).get("heightmap_rmse_m", np.nan))


_GT = {"feedback": "ground_truth", "renderer": "none"}

KNOBS: dict[str, Knob] = {
    "dynamics": Knob(
        "dynamics", "cart position error vs Radau (m)",
        tuple(Setting(f"{m} dt={dt:g}", {"integrator.method": m, "timing.dynamics_dt_s": dt})
              for m in ("rk4", "exponential", "radau") for dt in (0.1, 0.05, 0.02, 0.01, 0.005)),
        "exponential dt=0.01", _track_error, lambda label: "radau " + label.split(" ", 1)[1],
        {**_GT, "machine_sync.initial_long_error_m": -1.5, "machine_sync.initial_lat_error_m": 0.8}),
    "grain_cell": Knob(
        "grain_cell", "section mean height error vs 0.05 m cell (m)",
        tuple(Setting(f"cell={c:g}", {"grain.cell_m": c, "controller.grid_cell_m": c}) for c in (0.2, 0.1, 0.05)),
        "cell=0.1", _section_error, "cell=0.05", _GT),
    "render": Knob(
        "render", "mean LiDAR range error vs exact ray cast (m)",
        tuple(Setting(f"{n} cam {w}x{h}", {"sensor.method": "camera_rig", "render.rig": "fixed", "render.cameras": n,
                                            "render.width_px": w, "render.height_px": h, "render.hfov_deg": 100.0 / n})
              for n in (1, 2) for (w, h) in ((320, 240), (640, 480), (1024, 768)))
        + tuple(Setting(f"auto rig {b:g} deg", {"sensor.method": "camera_rig", "render.rig": "auto",
                                                 "sensor.max_angular_error_deg": b})
                for b in (0.05, 0.1, 0.2, 0.4))
        + (Setting("beam native", {"sensor.method": "beam_native"}),),
        "beam native", _range_error, None, {"feedback": "perception"}),
    "beams": Knob(
        "beams", "perceived height map RMSE (m)",
        tuple(Setting(f"{a}x{e} beams", {"sensor.pattern.azimuth_count": a, "sensor.pattern.elevation_count": e})
              for a, e in ((60, 40), (120, 80), (240, 160), (480, 320))),
        "240x160 beams", _height_rmse, None, {"feedback": "perception"}),
    "perception_grid": Knob(
        "perception_grid", "perceived height map RMSE (m)",
        tuple(Setting(f"grid={c:g}", {"controller.grid_cell_m": c}) for c in (0.3, 0.2, 0.1)),
        "grid=0.1", _height_rmse, None, {"feedback": "perception"}),
}


def run_study(scenario: Scenario, knobs: Sequence[str], out: Path, duration_s: float = 20.0,
              quiet: bool = True) -> Path:
    """Run the named knobs, write results.csv, study.md and study.png into ``out``; returns study.md. Each
    setting shows its own progress bar ("knob: setting") unless ``quiet``."""
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    panels = []
    for name in knobs:
        knob = KNOBS[name]
        base = apply_overrides(scenario, {**knob.base, "duration_s": duration_s})
        if name == "render" and base.renderer == "none":
            base = apply_overrides(base, {"renderer": "mock"})
        results = {}
        for st in knob.settings:
            log.info("study %s: %s", name, st.label)
            progress = run_progress(f"{name}: {st.label}", quiet)
            try:
                summary, series, arrays, cost = run_setting(apply_overrides(base, st.overrides), progress)
            finally:
                if progress is not None:
                    progress.close()
            results[st.label] = Result(st, summary, series, arrays, cost)
        pts = []
        for label, res in results.items():
            ref_label = knob.reference(label) if callable(knob.reference) else knob.reference
            err = knob.error(res, results[ref_label] if ref_label else None)
            pts.append((label, res.wall_per_sim_s, err))
            rows.append({"knob": name, "setting": label, "wall_s_per_sim_s": res.wall_per_sim_s, "error": err,
                         "error_label": knob.error_label, "default": label == knob.default,
                         "reference": label == ref_label})
        panels.append((name, knob.error_label, pts, knob.default))
    fig_study(panels).savefig(out / "study.png", dpi=DPI)
    with open(out / "results.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    lines = ["| knob | setting | wall s per sim s | error | |", "|---|---|---|---|---|"]
    for r in rows:
        tag = "default" if r["default"] else ("reference" if r["reference"] else "")
        lines.append(f"| {r['knob']} | {r['setting']} | {r['wall_s_per_sim_s']:.4f} | {r['error']:.3g} "
                     f"({r['error_label']}) | {tag} |")
    md = out / "study.md"
    md.write_text("\n".join(lines) + "\n")
    (out / "results.json").write_text(json.dumps(clean_json(rows), indent=2))
    return md
