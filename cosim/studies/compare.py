"""``launch.py compare SCENARIO``: the same scenario with ground-truth feedback and with perception feedback
(the paper-style estimator, and the fused estimator), then one HTML report of the paper's Figs 7-10 and metrics."""
from __future__ import annotations

import logging
from pathlib import Path

from cosim.report.html import write_comparison_report
from cosim.report.rundata import load_run
from cosim.runtime.launcher import launch
from cosim.runtime.progress import run_progress
from cosim.runtime.rundir import make_out_dir
from cosim.scenario.config import Scenario

__all__ = ["VARIANTS", "variants", "compare"]

log = logging.getLogger("cosim.studies.compare")

#: run name -> (feedback, estimator, sensor.method or None for the scenario's own): the paper-style run keeps the
#: paper's LiDAR pipeline (camera rig, Eqs 1-7) whatever the scenario uses, so the paper's method is reproduced
VARIANTS = {
    "ground_truth": ("ground_truth", "paper", None),
    "perception_paper": ("perception", "paper", "camera_rig"),
    "perception_fused": ("perception", "fused", None),
}

NOTES = ("Ground truth feeds the controller the exact height map. Perception feedback sees the pile through the "
         "simulated LiDAR: cells hidden behind the near wall, the pile's own crest or the grain stream have no "
         "return (holes), cells seen at grazing angles carry the nearest-pixel error, and every measurement is "
         "one or more frames old. The paper-style estimator takes each section's fullness from the perceived "
         "cells alone. The section being filled is exactly the one the falling stream hides and the mast views "
         "at a grazing angle, so its perceived peak lags or vanishes while grain arrives: the controller moves "
         "on late and the section overfills (the paper's Figs 9b and 10b). The fused estimator (ours) is a "
         "per-cell Kalman filter: every frame it deposits the volume the flow signal reports at the impact "
         "predicted from the spout's pose, with the heap law (a flat-topped cone at the angle of repose), and "
         "corrects that prediction with the perceived heights wherever they exist, each weighted by its "
         "variance; the measurement's latency is accounted for.")


def _with_lidar_method(scenario: Scenario, method: str | None) -> dict:
    """The update that sets the LiDAR's ``method`` (``sensor:``, or the ``kind: lidar`` entry of ``sensors:``);
    none for the scenario's own method or a scenario without a LiDAR (its cameras are compared as they are)."""
    lidar = scenario.lidar
    if method is None or lidar is None:
        return {}
    if not scenario.sensors:
        return {"sensor": lidar.model_copy(update={"method": method})}
    sensors = type(scenario.sensors)({n: (s.model_copy(update={"method": method}) if s.kind == "lidar" else s)
                                      for n, s in scenario.sensors.items()})
    return {"sensors": sensors}


def variants(scenario: Scenario) -> dict[str, Scenario]:
    """The scenarios compared, keyed by run name."""
    out = {}
    for name, (feedback, estimator, method) in VARIANTS.items():
        ctrl = scenario.controller.model_copy(update={"estimator": estimator})
        stereo = any(c.kind == "stereo_camera" for c in scenario.cameras.values())     # needs GL's textures
        renderer = scenario.renderer if scenario.renderer != "none" else ("gl" if stereo else "mock")
        out[name] = scenario.model_copy(update={"feedback": feedback, "controller": ctrl, "renderer": renderer,
                                                **_with_lidar_method(scenario, method)})
    return out


def compare(scenario: Scenario, out: Path, quiet: bool = True, *, overwrite: bool = False,
            parents: bool = True) -> Path:
    """Run every variant into ``out/<variant>`` and write ``out/report.html``; returns the report path. Each run
    shows its own progress bar labelled with its name (none when ``quiet``). ``out`` and the run directories in
    it follow cosim.runtime.rundir (``parents``: create ``out``'s missing parents; ``overwrite``: replace the
    runs of an earlier compare)."""
    make_out_dir(out, parents)
    runs = []
    for k, (name, sc) in enumerate(variants(scenario).items(), start=1):
        log.info("compare: running %s", name)
        progress = run_progress(f"[{k}/{len(VARIANTS)}] {name}", quiet)
        try:
            res = launch(sc, out / name, progress=progress, overwrite=overwrite)
        finally:
            if progress is not None:
                progress.close()
        runs.append(load_run(res.run_dir))
    return write_comparison_report(runs, out, NOTES)
