"""The built-in perception algorithm ``staged`` and its built-in stages (each ``builtin`` in its group), the
first implementations of :mod:`perception_proc.protocol`, loaded like a user's (cosim.scenario.plugins).

``staged`` runs ``ctx.stages``: rim (cart boundary) -> height map -> impact, then blanks the cells the stream
hides around the impact (:func:`perception_proc.estimates.impact.blank_under_stream`). Without a cart there is no map
and no impact. Each stage's answer is checked and a stage that raises or returns a bad value ends the run
naming that stage's plug-in.
"""
from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from cosim.errors import PluginFault
from perception_proc.estimates.heightmap import HeightMap, height_map
from perception_proc.estimates.impact import Impact, blank_under_stream, find_impact
from perception_proc.estimates.pointsigma import CAMERA_DEPTH, point_sigmas, wall_sigmas
from perception_proc.estimates.rim import CartEstimate, find_cart
from perception_proc.estimates.rimfit import fit_cart, within_gate
from perception_proc.protocol import (
    STAGE_POINTS,
    PerceptionContext,
    PerceptionInput,
    PerceptionOutput,
    check_cart,
    check_heightmap,
    check_impact,
)

__all__ = ["staged", "rim_stage", "heightmap_stage", "impact_stage", "NO_IMPACT_REASON"]

#: the impact's reason when there is no cart
NO_IMPACT_REASON = "no cart"
_MS_PER_S = 1e3


def rim_stage(ctx: PerceptionContext, inp: PerceptionInput) -> CartEstimate:
    """The cart rim from the level-frame points (perception_proc.estimates.rim.find_cart); where that finds no
    cart, or one outside the pose gate of Machine Sync's pose (a wrong group of rim-height points, which the
    gate would reject), and a depth camera sees, the known rim fitted to what is seen from Machine Sync's pose
    (perception_proc.estimates.rimfit.fit_cart), each point weighted by its sensor's expected error."""
    cart = find_cart(inp.points, inp.border, ctx.scenario.cart, inp.heading_xy, ctx.noise_sigma_m)
    prior = inp.cart_prior
    if prior is None or (cart.valid and within_gate(cart, prior)) or not any(
            f.kind in CAMERA_DEPTH and len(f.points) for f in inp.sensors.values()):
        return cart
    fit = fit_cart(inp.points, point_sigmas(ctx, inp), ctx.scenario.cart, inp.cart_prior)
    return fit if fit.valid else replace(cart, reason=f"{cart.reason}; {fit.reason}")


def heightmap_stage(ctx: PerceptionContext, inp: PerceptionInput, cart: CartEstimate) -> HeightMap:
    """Lower-cluster medians per cell in the perceived cart grid (perception_proc.estimates.heightmap.height_map), written
    into ``inp.heights_out`` when given; camera points kept clear of the walls by their own error
    (perception_proc.estimates.pointsigma.wall_sigmas)."""
    sc = ctx.scenario
    return height_map(inp.points, cart.level_from_grid, sc.cart, sc.controller.grid_cell_m,
                      sc.perception.min_points_per_cell, ctx.noise_sigma_m, out=inp.heights_out,
                      wall_sigma_xy=wall_sigmas(ctx, inp, cart.level_from_grid))


def impact_stage(ctx: PerceptionContext, inp: PerceptionInput, cart: CartEstimate, hm: HeightMap) -> Impact:
    """The stream's landing point from its returns and the height map (perception_proc.estimates.impact.find_impact),
    with the fitted axis moved away from the sensor."""
    lfg = cart.level_from_grid
    sensor_grid = (ctx.level_from_sensor[:3, 3] - lfg[:3, 3]) @ lfg[:3, :3]
    return find_impact(hm.grid_points, hm.stream, hm.heights, ctx.cell_xy,
                       ctx.scenario.perception.impact_search_radius_m, (float(sensor_grid[0]), float(sensor_grid[1])))


def _call(stage: str, ctx: PerceptionContext, *args):
    """Run stage ``stage`` of ``ctx.stages``; its failure is a PluginFault naming it (frame added by the caller)."""
    try:
        return getattr(ctx.stages, stage)(ctx, *args)
    except PluginFault:
        raise
    except Exception as e:  # noqa: BLE001 - a stage's failure ends the run with its name and cause
        raise PluginFault(ctx.stages.refs[stage], STAGE_POINTS[stage], f"raised {type(e).__name__}: {e}") from e


def staged(ctx: PerceptionContext, inp: PerceptionInput) -> PerceptionOutput:
    """Rim -> height map -> impact with the scenario's stages; ``timing_ms`` has 'cart', 'heightmap', 'impact'."""
    refs = ctx.stages.refs
    t1 = time.perf_counter()
    cart = check_cart(_call("rim", ctx, inp), refs["rim"], STAGE_POINTS["rim"])
    t2 = time.perf_counter()
    tm = {"cart": _MS_PER_S * (t2 - t1)}
    if not cart.valid:
        if inp.heights_out is not None:
            inp.heights_out.fill(np.nan)
        tm["heightmap"] = tm["impact"] = 0.0
        return PerceptionOutput(cart, None, Impact(False, np.full(3, np.nan), 0, NO_IMPACT_REASON), tm)
    hm = check_heightmap(_call("heightmap", ctx, inp, cart), ctx.grid, refs["heightmap"], STAGE_POINTS["heightmap"])
    t3 = time.perf_counter()
    imp = check_impact(_call("impact", ctx, inp, cart, hm), refs["impact"], STAGE_POINTS["impact"])
    if blank_under_stream(hm.heights, imp, ctx.cell_xy):
        hm = replace(hm, coverage=float(np.count_nonzero(np.isfinite(hm.heights)) / hm.heights.size))
    t4 = time.perf_counter()
    tm["heightmap"], tm["impact"] = _MS_PER_S * (t3 - t2), _MS_PER_S * (t4 - t3)
    return PerceptionOutput(cart, hm, imp, tm)

