"""The ``perception`` section of summary.json (docs/architecture.md) from a run's recorded series.

``series`` maps ``"perc_state.<field>"`` to a (frames,) float64 array, one entry per completed frame.
Accuracy fields are NaN on frames without an evaluation. Range statistics over the run weight each evaluated
frame by its number of compared beams; percentiles over the run are the beam-weighted mean of the per-frame
percentiles (the per-beam errors are not kept). NaN becomes ``null`` in the JSON. ``range_error.evaluation``
says how often the run was evaluated, or that evaluation was off (``perception.accuracy_every_frames: 0``).
"""
from __future__ import annotations

import math
from typing import Mapping

import numpy as np

import perception_proc.accuracy.sensors as cacc
import perception_proc.accuracy.stage as acc
from cosim.scenario.config import Scenario
from perception_proc.blocks import RANGE_BANDS_M, SENSOR_FIELDS, band_name, sensor_state_block

__all__ = ["summarize", "clean_json", "evaluation_caster", "evaluation_note", "sensor_blocks", "camera_fitness"]

_P = "perc_state."


def clean_json(x):
    """Recursively replace non-finite floats by None and numpy scalars by Python numbers."""
    if isinstance(x, dict):
        return {k: clean_json(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [clean_json(v) for v in x]
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return float(x) if math.isfinite(x) else None
    return x


def _col(series: Mapping[str, np.ndarray], name: str) -> np.ndarray:
    v = series.get(_P + name)
    return np.asarray(v, np.float64) if v is not None else np.zeros(0)


def _weighted(values: np.ndarray, weights: np.ndarray) -> float:
    ok = np.isfinite(values) & np.isfinite(weights) & (weights > 0)
    if not ok.any():
        return math.nan
    return float(np.sum(values[ok] * weights[ok]) / np.sum(weights[ok]))


def _median(values: np.ndarray) -> float:
    v = values[np.isfinite(values)]
    return float(np.median(v)) if v.size else math.nan


def evaluation_caster(scenario: Scenario) -> str | None:
    """The exact ray cast the accuracy evaluation ran (``perception_proc.accuracy.stage.exact_ranges``: Embree where
    embreex imports, else the numpy ray cast; one of ``cosim.world.fastcast.CASTERS``), None when it is off."""
    from cosim.world.fastcast import embree_available

    return None if scenario.perception.accuracy_every_frames == 0 else "embree" if embree_available() else "numpy"


def evaluation_note(scenario: Scenario) -> str:
    """How the run compared perception with the exact ray cast: ``every N frames, K beams`` or, with
    ``perception.accuracy_every_frames: 0``, a sentence saying that the accuracy fields are off (null)."""
    p = scenario.perception
    if p.accuracy_every_frames == 0:
        return ("off (perception.accuracy_every_frames: 0): no frame was compared with the exact ray cast, so the "
                "range-error, corner, impact and per-frame height-map errors are null")
    beams = f"{p.accuracy_beams} sampled beams" if p.accuracy_beams else "every beam"
    k = p.accuracy_every_frames
    return f"every {k} frame{'s' if k > 1 else ''}, {beams} each"


def summarize(scenario: Scenario, series: Mapping[str, np.ndarray], heightmap_truth: np.ndarray | None,
              heightmap_perceived: np.ndarray | None) -> dict:
    """``{"perception": {...}}``: final height-map RMSE and coverage, median corner and impact errors over the
    evaluated frames, range-error statistics overall, in the 2-15 m working range and per distance band."""
    shape = scenario.cart.grid_shape(scenario.controller.grid_cell_m)
    rmse = bias = cov = math.nan
    if heightmap_perceived is not None:
        per = np.asarray(heightmap_perceived)
        cov = float(np.count_nonzero(np.isfinite(per)) / max(per.size, 1))
        if heightmap_truth is not None:
            truth = acc.truth_on_grid(np.asarray(heightmap_truth), scenario.grain.cell_m, shape, scenario.cart)
            rmse, bias, cov = acc.heightmap_error(per, truth)
    n = _col(series, "range_beams")
    evaluated = _col(series, "acc_evaluated")
    bands = []
    for lo, hi in RANGE_BANDS_M:
        b = band_name(lo, hi)
        w = _col(series, f"rerr_{b}_n")
        bands.append({
            "lo_m": lo, "hi_m": hi, "beams": float(np.nansum(w)) if w.size else 0.0,
            "mean_m": _weighted(_col(series, f"rerr_{b}_mean_m"), w),
            "p99_m": _weighted(_col(series, f"rerr_{b}_p99_m"), w),
            "frac_above_5cm": _weighted(_col(series, f"rerr_{b}_above5_frac"), w),
        })
    wr = sum(_col(series, f"rerr_{band_name(lo, hi)}_n") for lo, hi in RANGE_BANDS_M if 2.0 <= lo and hi <= 15.0) \
        if n.size else np.zeros(0)
    maxes = _col(series, "range_err_max_m")
    range_error = {
        "evaluation": evaluation_note(scenario),
        "ray_caster": evaluation_caster(scenario),
        "frames_evaluated": int(np.nansum(evaluated)) if evaluated.size else 0,
        "beams_per_frame": scenario.perception.accuracy_beams or "all",
        "beams": float(np.nansum(n)) if n.size else 0.0,
        "mean_m": _weighted(_col(series, "range_err_mean_m"), n),
        "median_m": _median(_col(series, "range_err_median_m")),
        "p99_m": _weighted(_col(series, "range_err_p99_m"), n),
        "max_m": float(np.nanmax(maxes)) if np.isfinite(maxes).any() else math.nan,
        "frac_above_5cm": _weighted(_col(series, "frac_above_5cm"), n),
        "working_range_m": list(acc.WORKING_RANGE_M),
        "working_mean_m": _weighted(_col(series, "range_err_mean_2_15_m"), wr) if n.size else math.nan,
        "working_frac_above_5cm": _weighted(_col(series, "frac_above_5cm_2_15"), wr) if n.size else math.nan,
        "working_p99_m": _weighted(_col(series, "range_err_p99_2_15_m"), wr) if n.size else math.nan,
        "beam_missing_frac": _weighted(_col(series, "beam_missing_frac"), n),
        "bands": bands,
    }
    cart_valid = _col(series, "cart_valid")
    impact_valid = _col(series, "impact_valid")
    out = {
        "heightmap_rmse_m": rmse,
        "heightmap_bias_m": bias,
        "coverage": cov,
        "corner_error_m": _median(_col(series, "corner_error_m")),
        "impact_error_m": _median(_col(series, "impact_error_m")),
        "heightmap_rmse_median_m": _median(_col(series, "heightmap_rmse_m")),
        "cart_found_fraction": float(np.mean(cart_valid)) if cart_valid.size else math.nan,
        "impact_found_fraction": float(np.mean(impact_valid)) if impact_valid.size else math.nan,
        "sampler": scenario.perception.sampler,
        "range_error": range_error,
        "timing_ms": {k: _median(_col(series, f"{k}_ms"))
                      for k in ("lidar", "cart", "heightmap", "impact", "perception", "accuracy")},
    }
    out["sensors"] = sensor_blocks(scenario, series, range_error, heightmap_truth, heightmap_perceived)
    out["fitness"] = fitness(scenario, series)
    for name, verdict in camera_fitness(scenario, series).items():
        out["sensors"][name]["fit"] = verdict
        if verdict["left_out_frames"]:
            out["fitness"].setdefault("left_out", {})[name] = verdict["reason"]
    return {"perception": clean_json(out)}


def fitness(scenario: Scenario, series: Mapping[str, np.ndarray]) -> dict:
    """Whether the cameras' expected error at the cart supports the fill target (perception_proc.cameras.expected):
    ``unfit_frames`` (frames whose height map was withheld: a camera unfit and no fit sensor left,
    perception_proc.selection) of ``frames_at_cart`` (frames with a camera seeing the found cart), the median expected
    1-sigma of a cell's height ``height_sigma_m`` at the median depth ``depth_m``, what the target allows
    (``allowed_sigma_m``: the overfill tolerance over FIT_SIGMAS) and ``reason``, a sentence naming the figure
    when every frame at the cart was unfit (perception withheld its height map, so the controller never started
    the auger), else None."""
    from perception_proc.cameras.expected import FIT_SIGMAS, error_basis

    sigma, depth, unfit = (_col(series, k) for k in ("height_sigma_m", "height_sigma_depth_m", "sensor_unfit"))
    seen = np.isfinite(sigma) if sigma.size else np.zeros(0, bool)
    allowed = scenario.outcome.overfill_tolerance_m / FIT_SIGMAS
    out = {"frames_at_cart": int(np.count_nonzero(seen)), "unfit_frames": int(np.nansum(unfit)) if unfit.size else 0,
           "height_sigma_m": _median(sigma[seen]) if seen.any() else math.nan,
           "depth_m": _median(depth[seen]) if seen.any() else math.nan, "allowed_sigma_m": allowed, "reason": None}
    if out["frames_at_cart"] and out["unfit_frames"] == out["frames_at_cart"]:
        basis = "; ".join(f"{n}: {error_basis(c)}" for n, c in scenario.cameras.items() if error_basis(c))
        out["reason"] = (f"the cameras' expected error of a cell's height at the cart, {100 * out['height_sigma_m']:.1f}"
                         f" cm at {out['depth_m']:.1f} m ({basis}), exceeds the {100 * allowed:.1f} cm the "
                         f"{100 * scenario.outcome.overfill_tolerance_m:.0f} cm overfill tolerance allows: no height "
                         "map was published and the auger was not started")
    return out


def camera_fitness(scenario: Scenario, series: Mapping[str, np.ndarray]) -> dict:
    """Per depth camera with a ``sensor_<name>`` record (perception_proc.selection): ``frames_at_cart`` (frames
    it saw the found cart), ``unfit_frames``, ``left_out_frames`` (frames its points were not fused), the median
    ``height_sigma_m`` and ``depth_m`` over the frames at the cart, and ``reason``: a sentence naming the figure
    when it was left out of the fusion, or saying that it never saw the cart where others found it, else None."""
    from perception_proc.cameras.expected import FIT_SIGMAS, error_basis

    out = {}
    tol = scenario.outcome.overfill_tolerance_m
    for name in scenario.depth_sensors:
        block = sensor_state_block(name)
        if scenario.sensor_set[name].kind == "lidar" or f"{block}.cart_sigma_m" not in series:
            continue
        sigma, depth, unfit, fused = (np.asarray(series[f"{block}.{k}"], np.float64)
                                      for k in ("cart_sigma_m", "cart_depth_m", "unfit", "fused"))
        seen = np.isfinite(sigma)
        v = {"frames_at_cart": int(np.count_nonzero(seen)), "unfit_frames": int(np.nansum(unfit)),
             "left_out_frames": int(np.count_nonzero(fused == 0)),
             "height_sigma_m": _median(sigma[seen]) if seen.any() else math.nan,
             "depth_m": _median(depth[seen]) if seen.any() else math.nan, "reason": None}
        carts = int(np.nansum(_col(series, "cart_valid")))
        if not v["frames_at_cart"] and carts:
            v["reason"] = (f"camera {name}: never saw the found cart ({carts} frames with a cart): none of its points "
                           "reached the cart's height map")
        if v["left_out_frames"]:
            v["reason"] = (f"camera {name}: expected error of a cell's height at the cart {100 * v['height_sigma_m']:.1f}"
                           f" cm at {v['depth_m']:.1f} m ({error_basis(scenario.cameras[name])}), more than the {100 * tol / FIT_SIGMAS:.1f} cm the "
                           f"{100 * tol:.0f} cm overfill tolerance allows: left out of the fusion in "
                           f"{v['left_out_frames']} of {fused.size} frames, the fit sensors fused")
        out[name] = v
    return out


def _fill_final(scenario: Scenario, truth: np.ndarray | None, perceived: np.ndarray | None) -> dict:
    """The fill-height figures of the final perceived map against the final truth (the shorthand LiDAR, whose
    own map is the perceived map and has no per-frame record)."""
    if truth is None or perceived is None:
        return {"mean_rel_error": math.nan, "bias_m": math.nan, "cells": 0, "over": "final map"}
    shape = scenario.cart.grid_shape(scenario.controller.grid_cell_m)
    f = cacc.fill_error(perceived, acc.truth_on_grid(np.asarray(truth), scenario.grain.cell_m, shape, scenario.cart))
    return {"mean_rel_error": f["fill_rel_err"], "bias_m": f["fill_bias_m"], "cells": f["fill_cells"],
            "over": "final map"}


def sensor_blocks(scenario: Scenario, series: Mapping[str, np.ndarray], lidar_range: dict,
                  truth: np.ndarray | None, perceived: np.ndarray | None) -> dict:
    """``perception.sensors``: per depth-giving sensor, its depth error against the exact ray cast in its working
    range (mean, median, p99, share above 5 cm: weighted by the compared pixels of each evaluated frame), its
    coverage, its valid share, the model's time, and the mean relative error of the fill height its own map
    gives (over the evaluated frames; for the ``sensor:`` shorthand, of the final perceived map)."""
    out = {}
    for name in scenario.depth_sensors:
        spec = scenario.sensor_set[name]
        lo, hi = (acc.WORKING_RANGE_M if spec.kind == "lidar" else (spec.range_min_m, spec.range_max_m))
        if not scenario.sensors:                                  # the shorthand: perc_state holds it all
            out[name] = {"kind": "lidar", "working_range_m": [lo, hi],
                         "frames_evaluated": lidar_range["frames_evaluated"],
                         "depth_error": {"mean_m": lidar_range["working_mean_m"],
                                         "p99_m": lidar_range["working_p99_m"],
                                         "frac_above_5cm": lidar_range["working_frac_above_5cm"]},
                         "coverage": 1.0 - lidar_range["beam_missing_frac"]
                         if math.isfinite(lidar_range["beam_missing_frac"]) else math.nan,
                         "fill_height": _fill_final(scenario, truth, perceived)}
            continue
        col = {f: np.asarray(series.get(f"{sensor_state_block(name)}.{f}", np.zeros(0)), np.float64)
               for f, _, _, _ in SENSOR_FIELDS}
        n, cells = col["depth_pixels"], col["fill_cells"]
        out[name] = {
            "kind": spec.kind, "working_range_m": [lo, hi],
            "frames_evaluated": int(np.nansum(col["acc_evaluated"])) if col["acc_evaluated"].size else 0,
            "depth_error": {"mean_m": _weighted(col["depth_err_mean_m"], n),
                            "median_m": _median(col["depth_err_median_m"]),
                            "p99_m": _weighted(col["depth_err_p99_m"], n),
                            "frac_above_5cm": _weighted(col["frac_above_5cm"], n)},
            "coverage": _weighted(col["coverage"], np.ones_like(col["coverage"])),
            "spurious_frac": _weighted(col["spurious_frac"], np.ones_like(col["spurious_frac"])),
            "valid_fraction": _median(col["valid_fraction"]),
            "fill_height": {"mean_rel_error": _weighted(col["fill_rel_err"], cells),
                            "bias_m": _weighted(col["fill_bias_m"], cells),
                            "cells": _median(np.where(cells > 0, cells, np.nan)), "over": "evaluated frames"},
            "measure_ms": _median(col["measure_ms"]),
        }
    return out
