"""How a perception run's cost grows: CPU per frame against beams and against the grain grid, each curve measured
side by side in one process (sweep throughput with 1 and 2 local workers: the ``sweep_throughput`` case).

* beams: the default scenario with its LiDAR pattern (the honeycomb over the same 90 x 95 deg field) at several
  densities, 10,000 to 300,000 beams, the 128 x 2048 pattern among them. One in-process session per point
  (``cosim.runtime.inprocess``: the launched run's participants and blocks, GL renderer), all open at once and
  stepped frame by frame in rotating order, so that every point sees the same machine; CPU per frame of each ring
  member's step (process CPU over the step: llvmpipe's threads included), medians over ``frames`` after ``warmup``.
  The cost per beam is the slope of a least-squares line through the points.
* cells: the same with ``grain.cell_m`` 0.1 to 0.025 m (cells per cart 1,800 to 28,800).
* sensors: the default scenario's LiDAR (beam-native) and 0 to 3 depth cameras beside it (the ``sensor_cost`` case's
  Kinect-class camera, 512 x 424, an image every frame; a scenario has at most one LiDAR); the cost per added
  camera is the slope. What each other kind costs: the ``sensor_cost`` case.
"""
from __future__ import annotations

import statistics
import time

from harness import Context, case, rotating

__all__ = ["beams_curve", "cells_curve", "curves", "fit_per_unit", "interleaved_sessions", "sensors_curve"]

#: (label, azimuth_count, elevation_count) of the beam curve: the default field at these densities
BEAM_POINTS = (("100 x 100", 100, 100), ("240 x 160 (the default)", 240, 160), ("400 x 250", 400, 250),
               ("2048 x 128 (the 128 x 2048 pattern)", 2048, 128), ("600 x 500", 600, 500))
#: grain cells of the grid curve, m
CELL_POINTS = (0.1, 0.075, 0.05, 0.025)
MEMBERS = ("dynamics", "renderer", "perception")
#: depth cameras beside the LiDAR on the sensors curve
CAMERA_POINTS = (0, 1, 2, 3)


def interleaved_sessions(scenarios: dict, frames: int, warmup: int) -> dict[str, dict[str, float]]:
    """Median CPU ms per frame of each member's step, per labelled scenario, all sessions stepped in turn."""
    from cosim.runtime.heap import keep_heap
    from cosim.runtime.inprocess import InProcessSession

    keep_heap()
    sessions, cpu = {}, {}
    try:
        for label, sc in scenarios.items():
            sess = InProcessSession(sc, frames=warmup + frames)
            sessions[label] = sess
            cpu[label] = {m: [] for m in sess.participants}
            for name, p in sess.participants.items():
                step, into = p.step, cpu[label][name]

                def timed(frame, step=step, into=into):
                    c = time.process_time()
                    rest = step(frame)
                    own = time.process_time() - c
                    if rest is None:
                        into.append(own)
                        return None

                    def timed_rest(rest=rest, own=own):
                        c2 = time.process_time()
                        rest()
                        into.append(own + time.process_time() - c2)
                    return timed_rest
                p.step = timed
        labels = list(sessions)
        for k in range(warmup + frames + 1):
            for label in rotating(labels, k):
                sessions[label].step()
    finally:
        for sess in sessions.values():
            sess.close()
    out = {}
    for label, per in cpu.items():
        out[label] = {m: 1e3 * statistics.median(v[warmup:]) for m, v in per.items() if len(v) > warmup}
        out[label]["total"] = sum(out[label].values())
    return out


def fit_per_unit(xs: list[float], ys: list[float]) -> tuple[float, float]:
    """(slope, intercept) of the least-squares line y = slope x + intercept."""
    n = len(xs)
    mx, my = sum(xs) / n, sum(ys) / n
    sxx = sum((x - mx) ** 2 for x in xs)
    slope = sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / sxx if sxx else float("nan")
    return slope, my - slope * mx


def beams_curve(ctx: Context, frames: int, warmup: int, points=BEAM_POINTS) -> dict:
    """CPU ms per frame of each member at each beam count; ns per beam and frame (slopes)."""
    scenarios, beams = {}, {}
    for label, az, el in points:
        scenarios[label] = ctx.scenario(extra={"sensor": {"pattern": {"azimuth_count": az, "elevation_count": el}}})
        beams[label] = az * el
    res = interleaved_sessions(scenarios, frames, warmup)
    xs = [beams[k] for k in res]
    slopes = {m: 1e6 * fit_per_unit(xs, [res[k][m] for k in res])[0] for m in ("renderer", "perception", "total")}
    return {"CPU per frame against beams (ms)": {k: {"beams": beams[k], **res[k]} for k in res},
            "cost per beam (slope of a least-squares line)": {"ns per beam and frame": slopes}}


def cells_curve(ctx: Context, frames: int, warmup: int, points=CELL_POINTS) -> dict:
    """CPU ms per frame of each member at each grain cell size; us per cell and frame (slopes)."""
    scenarios, cells = {}, {}
    for cell in points:
        sc = ctx.scenario(extra={"grain": {"cell_m": cell}})
        label = f"{cell:g} m"
        scenarios[label] = sc
        cells[label] = sc.cart.grid_shape(cell)[0] * sc.cart.grid_shape(cell)[1]
    res = interleaved_sessions(scenarios, frames, warmup)
    xs = [cells[k] for k in res]
    slopes = {m: 1e3 * fit_per_unit(xs, [res[k][m] for k in res])[0] for m in (*MEMBERS, "total")}
    return {"CPU per frame against the grain grid (ms)": {k: {"cells": cells[k], **res[k]} for k in res},
            "cost per cell (slope)": {"us per cell and frame": slopes}}


def sensors_curve(ctx: Context, frames: int, warmup: int, points=CAMERA_POINTS) -> dict:
    """CPU ms per frame of each member with the LiDAR and 0..3 depth cameras; ms per added camera (slopes)."""
    import json

    from cases.sensors import TOF
    from cosim.scenario.config import Scenario

    base = ctx.scenario()
    data = base.model_dump(mode="json")
    lidar = {"kind": "lidar", **data.pop("sensor")}
    scenarios = {}
    for n in points:
        sensors = {"lidar": lidar, **{f"tof{k}": TOF for k in range(n)}}
        scenarios[f"LiDAR + {n} depth camera(s)"] = Scenario.model_validate_json(json.dumps({**data, "sensors": sensors}))
    res = interleaved_sessions(scenarios, frames, warmup)
    xs = [int(k.split(" + ")[1].split()[0]) for k in res]
    slopes = {m: fit_per_unit(xs, [res[k].get(m, 0.0) for k in res])[0] for m in (*MEMBERS, "total")}
    return {"CPU per frame against sensors (ms)": {k: {"depth cameras": x, **res[k]} for k, x in zip(res, xs)},
            "cost per depth camera (slope)": {"ms per camera and frame": slopes}}


@case("curves", "how the cost grows: CPU per frame of each member against beams, the grain grid and sensors",
      options={"only": "beams,cells,sensors", "frames": 60, "warmup": 100}, quick={"frames": 3, "warmup": 2},
      settings=True)
def curves(ctx: Context) -> dict:
    """Every curve in ``only`` (module docstring); ``--quick``: two points of each curve."""
    only = ctx["only"].split(",")
    out: dict = {}
    if "beams" in only:
        out.update(beams_curve(ctx, ctx["frames"], ctx["warmup"], BEAM_POINTS[:2] if ctx.quick else BEAM_POINTS))
    if "cells" in only:
        out.update(cells_curve(ctx, ctx["frames"], ctx["warmup"], CELL_POINTS[::2] if ctx.quick else CELL_POINTS))
    if "sensors" in only:
        out.update(sensors_curve(ctx, ctx["frames"], ctx["warmup"], CAMERA_POINTS[:2] if ctx.quick else CAMERA_POINTS))
    return out
