"""``launch.py study``: error against run time over the fidelity knobs.

Each knob is a list of settings (dotted-path overrides of the scenario). The study is a sweep (same engine and
results table as ``launch.py sweep``, cosim/studies/sweep.py): every setting is one launched run of a short
duration, into ``OUT/runs/<id>/``. Its error is measured against the knob's highest-fidelity setting or an
absolute reference (the exact ray cast, the ground-truth height map), its cost as the median wall time of a
frame per simulated second (process start-up excluded). Besides the sweep's results.csv the study writes
study.csv, study.md and one plot per knob of error against run time with the default marked (study.png).
User knobs (``--knob NAME=PATH:V1,V2,...``) vary one field; their error is the final section mean height's
largest difference from the last value's run.
"""
from __future__ import annotations

import csv
import json
import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
import yaml
from pydantic import ValidationError

from cosim.errors import Problem, ScenarioError
from cosim.report.figures import DPI, fig_study
from cosim.runtime.outputs import clean_json
from cosim.scenario.config import Scenario
from cosim.scenario.yamlmarks import Loader

from .results import read_summary
from .sweep import run_sweep
from .sweepfile import RunSpec, Sweep, run_id

__all__ = ["Setting", "Knob", "KNOBS", "KNOB_FILE", "apply_overrides", "parse_knob", "study_sweep", "run_study"]

log = logging.getLogger("cosim.studies.study")


@dataclass(frozen=True)
class Setting:
    label: str
    overrides: dict = field(default_factory=dict)


@dataclass
class Result:
    """One setting's run: its summary, its time series (column -> array) and its cost."""

    setting: Setting
    summary: dict
    series: dict
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


#: pseudo file name of problems in ``--knob`` options
KNOB_FILE = "<--knob>"


def parse_knob(text: str, index: int = 1) -> Knob:
    """A user knob from ``NAME=PATH:V1,V2,...`` (values as YAML scalars); the last value is the reference."""
    name, sep, rest = text.partition("=")
    path, sep2, values = rest.partition(":")
    items = [yaml.load(v, Loader=Loader) for v in values.split(",") if v.strip()] if sep2 else []
    if not (sep and sep2 and name.strip() and path.strip()) or len(items) < 2:
        raise ScenarioError([Problem(KNOB_FILE, index, 1, "", f"malformed knob {text!r}: expected "
                                     "NAME=PATH:V1,V2[,...] with at least two values, e.g. "
                                     "cell=grain.cell_m:0.2,0.1,0.05")])
    path = path.strip()
    settings = tuple(Setting(f"{path.rsplit('.', 1)[-1]}={v}", {path: v}) for v in items)
    return Knob(name.strip(), f"section mean height error vs {settings[-1].label} (m)", settings, "",
                _section_error, settings[-1].label)


def _knob_base(scenario: Scenario, knob: Knob, duration_s: float) -> Scenario:
    base = apply_overrides(scenario, {**knob.base, "duration_s": duration_s})
    if knob.name == "render" and base.renderer == "none":
        base = apply_overrides(base, {"renderer": "mock"})
    return base


def study_sweep(scenario: Scenario, knobs: Sequence[Knob], duration_s: float) -> Sweep:
    """The study as a sweep: one run per knob setting, labelled with its knob and setting. Raises ScenarioError
    naming the knob and setting when a setting's overrides are not a valid scenario."""
    runs, problems, params = [], [], {}
    for i, knob in enumerate(knobs, start=1):
        base = _knob_base(scenario, knob, duration_s)
        for st in knob.settings:
            try:
                sc = apply_overrides(base, st.overrides)
            except (KeyError, ValidationError) as exc:
                msg = str(exc).strip("'\"").replace("\n", " ")
                problems.append(Problem(KNOB_FILE, i, 1, f"{knob.name}.{st.label}", msg))
                continue
            params.update(dict.fromkeys(st.overrides))
            fixed = {**knob.base, "duration_s": duration_s, "scenario": scenario.model_dump(mode="json")}
            runs.append(RunSpec(run_id(knob.name, fixed, st.overrides, sc.seed), dict(st.overrides), sc.seed, sc,
                                {"knob": knob.name, "setting": st.label}))
    if problems:
        raise ScenarioError(problems)
    return Sweep(f"study-{scenario.name}", tuple(params), tuple(runs), ("knob", "setting"))


def _series(run_dir: Path) -> dict:
    """A run's timeseries.csv as column -> array (empty when it has none)."""
    try:
        with open(run_dir / "timeseries.csv", newline="") as f:
            header = next(csv.reader(f))
            data = np.loadtxt(f, delimiter=",", ndmin=2)
    except (OSError, StopIteration, ValueError):
        return {}
    return {name: data[:, i] for i, name in enumerate(header)}


def _result(run: RunSpec, out: Path, setting: Setting) -> Result | None:
    summary = read_summary(out / "runs" / run.id)
    if not summary or not summary.get("completed"):
        return None
    frame_ms = (summary.get("timing_ms") or {}).get("frame")
    period = run.scenario.timing.sensor_period_s
    cost = frame_ms / 1000.0 / period if frame_ms else summary["wall_time_s"] / max(summary["sim_time_s"], 1e-9)
    return Result(setting, summary, _series(out / "runs" / run.id), cost)


def run_study(scenario: Scenario, knobs: Sequence[str | Knob], out: Path, duration_s: float = 20.0, *,
              jobs: int | None = 1, scheduler: str | None = None, quiet: bool = True, parents: bool = True) -> Path:
    """Run the knobs (names of :data:`KNOBS` or :class:`Knob`) as a sweep into ``out`` (``parents``: create its
    missing parents too); write study.csv, study.md, study.json and study.png beside the sweep's results.csv;
    returns study.md.

    ``jobs`` defaults to 1 so that runs do not share cores: the cost axis is a wall time.
    """
    knobs = [KNOBS[k] if isinstance(k, str) else k for k in knobs]
    sweep = study_sweep(scenario, knobs, duration_s)
    run_sweep(sweep, out, jobs=jobs, scheduler=scheduler, quiet=quiet, figures=False, parents=parents)
    rows, panels = [], []
    runs = iter(sweep.runs)
    for knob in knobs:
        results = {st.label: _result(next(runs), out, st) for st in knob.settings}
        pts = []
        for label, res in results.items():
            ref_label = knob.reference(label) if callable(knob.reference) else knob.reference
            ref = results.get(ref_label) if ref_label else None
            err = float("nan") if res is None or (ref_label and ref is None) else knob.error(res, ref)
            cost = float("nan") if res is None else res.wall_per_sim_s
            pts.append((label, cost, err))
            rows.append({"knob": knob.name, "setting": label, "wall_s_per_sim_s": cost, "error": err,
                         "error_label": knob.error_label, "default": label == knob.default,
                         "reference": label == ref_label, "completed": res is not None})
        panels.append((knob.name, knob.error_label, [p for p in pts if np.isfinite(p[1]) and np.isfinite(p[2])],
                       knob.default))
    fig_study(panels).savefig(out / "study.png", dpi=DPI)
    with open(out / "study.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    lines = ["| knob | setting | wall s per sim s | error | |", "|---|---|---|---|---|"]
    for r in rows:
        tag = "default" if r["default"] else ("reference" if r["reference"] else "")
        tag = tag if r["completed"] else "failed (see results.csv)"
        lines.append(f"| {r['knob']} | {r['setting']} | {r['wall_s_per_sim_s']:.4f} | {r['error']:.3g} "
                     f"({r['error_label']}) | {tag} |")
    md = out / "study.md"
    md.write_text("\n".join(lines) + "\n")
    (out / "study.json").write_text(json.dumps(clean_json(rows), indent=2))
    return md

