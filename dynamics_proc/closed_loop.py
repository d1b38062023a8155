"""A pure closed loop of the system model, no segment: for acceptance tests, studies and benchmarks.

Applies the runtime's latency rule: at frame m the controller acts on the measurement of frame m - 1 - L
(L = ``timing.latency_frames``), "no measurement" before frame 0. The measurement is the ground-truth height
map resampled to the controller grid, optionally passed through ``measure`` (e.g. holes and noise standing in
for perception).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from cosim.scenario.config import Scenario
from dynamics_proc.fmu.models import open_fmus
from dynamics_proc.model import ModelParams, World, initial_world, signals, step_frame, truth_measurement

__all__ = ["SimResult", "simulate", "Measure", "noisy_measurement", "occluded_measurement", "DONE_GRACE_FRAMES"]

#: frames still simulated after the controller declares the cart full and the flow has stopped
DONE_GRACE_FRAMES = 5

#: measure(truth on the controller grid (nxc, nyc) m, frame) -> measured map (NaN holes) or None
Measure = Callable[[np.ndarray, int], "np.ndarray | None"]


@dataclass(frozen=True)
class SimResult:
    """``series``: column ``"dyn_state.<field>"`` -> (frames + 1,) float64 (frame 0 included);
    ``heights``: final truth height map (nx, ny) float64 m; ``world``: the final state; ``wall_s``: run time."""

    series: dict[str, np.ndarray]
    heights: np.ndarray
    world: World
    wall_s: float


def noisy_measurement(seed: int, holes: float, sigma_m: float) -> Measure:
    """A ``measure`` hook that degrades the truth map like a perceived one: Gaussian noise of ``sigma_m`` (m)
    on every cell, then a random fraction ``holes`` of cells NaN. Seeded, so runs repeat."""
    rng = np.random.default_rng(seed)

    def measure(truth, frame):
        out = truth + rng.normal(0.0, sigma_m, truth.shape)
        out[rng.random(truth.shape) < holes] = np.nan
        return out
    return measure


def occluded_measurement(seed: int, holes: float, sigma_m: float, radius_m: float, cell_m: float) -> Measure:
    """Like :func:`noisy_measurement`, and also hides a disc of ``radius_m`` around the cell that rose most
    since the previous frame: where grain is arriving, the view the falling stream blocks (the paper's
    degradation). ``cell_m``: the controller grid's cell. Seeded."""
    rng = np.random.default_rng(seed)
    prev: list[np.ndarray] = []

    def measure(truth, frame):
        out = truth + rng.normal(0.0, sigma_m, truth.shape)
        out[rng.random(truth.shape) < holes] = np.nan
        if prev and float(np.max(truth - prev[0])) > 0.0:
            i, j = np.unravel_index(np.argmax(truth - prev[0]), truth.shape)
            ii, jj = np.ogrid[:truth.shape[0], :truth.shape[1]]
            out[((ii - i) ** 2 + (jj - j) ** 2) * cell_m ** 2 <= radius_m ** 2] = np.nan
        prev[:] = [truth]
        return out
    return measure


def simulate(scenario: Scenario, frames: int | None = None, measure: Measure | None = None,
             stop_when_done: bool = False, params: ModelParams | None = None) -> SimResult:
    """Run frames 0..``frames`` (default ``scenario.frames``) with height-map feedback.

    ``stop_when_done``: end early, DONE_GRACE_FRAMES after the cart is declared full and the flow stopped.
    The scenario's FMUs (dynamics_proc.fmu.models) are opened for the run and freed after it (unless ``params``
    are given: then they hold them).
    """
    fmus = open_fmus(scenario) if params is None else None
    try:
        return _simulate(scenario, params or ModelParams.from_scenario(scenario, fmus), frames, measure,
                         stop_when_done)
    finally:
        if fmus is not None:
            fmus.close()


def _simulate(scenario: Scenario, p: ModelParams, frames: int | None, measure: Measure | None,
              stop_when_done: bool) -> SimResult:
    n = scenario.frames if frames is None else frames
    lat = scenario.timing.latency_frames
    t0 = time.perf_counter()
    w = initial_world(scenario, p)
    rows = [signals(w, p)]
    history: dict[int, np.ndarray | None] = {0: _measure(w, p, measure)}
    done_at = -1
    for m in range(1, n + 1):
        meas = history.pop(m - 1 - lat, None)
        w = step_frame(w, meas, p)
        history[m] = _measure(w, p, measure)
        rows.append(signals(w, p))
        if stop_when_done:
            if done_at < 0 and w.out.all_full and w.flow_level == 0.0:
                done_at = m
            if done_at >= 0 and m - done_at >= DONE_GRACE_FRAMES:
                break
    wall = time.perf_counter() - t0
    series = {f"dyn_state.{k}": np.array([r[k] for r in rows], dtype=np.float64) for k in rows[0]}
    return SimResult(series, w.heights, w, wall)


def _measure(w: World, p: ModelParams, measure: Measure | None) -> np.ndarray | None:
    truth = truth_measurement(w.heights, p)
    return truth if measure is None else measure(truth, w.frame)
