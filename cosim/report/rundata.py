"""Read a run directory back: resolved scenario, summary, timeseries (and timing) columns and final height maps."""
from __future__ import annotations

import csv
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from cosim.scenario.config import Scenario

__all__ = ["RunData", "load_run"]


@dataclass
class RunData:
    """One run's outputs. ``series`` maps column name -> (frames,) float64; maps are (nx, ny) float32 or None."""

    path: Path
    scenario: Scenario
    summary: dict
    series: dict[str, np.ndarray]
    heightmap_truth: np.ndarray | None
    heightmap_perceived: np.ndarray | None

    def col(self, name: str) -> np.ndarray | None:
        """A column by full name (``dyn_state.t_s``) or by field name alone (``t_s``); None if absent."""
        if name in self.series:
            return self.series[name]
        hits = [k for k in self.series if k.split(".", 1)[-1] == name]
        return self.series[hits[0]] if hits else None

    @property
    def t(self) -> np.ndarray:
        """Sim time of each recorded frame, s."""
        t = self.col("dyn_state.t_s")
        if t is None:
            t = self.series["frame"] * self.scenario.timing.sensor_period_s
        return t


def _csv_columns(path: Path) -> dict[str, np.ndarray]:
    """Column name -> (rows,) float64 of a CSV file written by the recorder; {} when it does not exist."""
    if not path.exists():
        return {}
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    if not rows:
        return {}
    header, body = rows[0], rows[1:]
    data = np.array(body, dtype=np.float64) if body else np.zeros((0, len(header)))
    return {h: data[:, i] for i, h in enumerate(header)}


def load_run(path: str | Path) -> RunData:
    """Load a run directory written by :func:`cosim.runtime.launcher.launch`."""
    path = Path(path)
    scenario = Scenario.model_validate_json(json.dumps(yaml.safe_load((path / "scenario.yaml").read_text())))
    summary = json.loads((path / "summary.json").read_text())
    series = _csv_columns(path / "timeseries.csv")
    timing = _csv_columns(path / "timing.csv")  # the wall-clock columns, same frames (cosim.runtime.recorder)
    series.update({k: v for k, v in timing.items() if k != "frame" and len(v) == len(series.get("frame", v))})

    def npy(name: str) -> np.ndarray | None:
        p = path / f"{name}.npy"
        return np.load(p) if p.exists() else None

    return RunData(path, scenario, summary, series, npy("heightmap_truth"), npy("heightmap_perceived"))
