"""A stand-in for a Simulink model that keeps the master: it drives graincosim's exported world (GrainWorld.fmu,
written by build.py) with fmpy, closing the loop through the world's perception with vehicle and controller
equations of its own, as a Simulink model would hold them in blocks. Nothing here imports graincosim.

Vehicles (one update per 0.1 s frame, the FMU's step): the combine drives straight at ``combine_speed_mps``; the
cart rides beside it at a lateral offset and a longitudinal offset that follows the controller's setpoint with a
first-order lag (``tau_s``), as Machine Sync holds it; the tractor keeps its place ahead of the cart; the spout is
fixed on the combine. Their offsets are taken from the FMU's start values (the scenario's initial scene). The auger
ramps the flow up over ``spool_up_s`` when on and down over ``run_out_s`` when off.

Controller (perception feedback only: the FMU's ``perceived_*`` outputs): sections are filled front to back; a
section is done when its perceived fullness reaches ``full_at``; the impact is predicted as the spout's position
over the cart (from the master's own poses) plus the drift the perception measured (perceived impact minus spout,
low-pass filtered); the cart's longitudinal setpoint moves the prediction to the section's centre (kept
``aim_margin_m`` inside the end walls; at most ``max_rate_mps``), and the auger runs while the prediction is within
``on_tolerance_m`` of it and safely inside the walls.

    python examples/simulink_master/build.py && python examples/simulink_master/master.py
"""
from __future__ import annotations

import math
import os
import shutil
from dataclasses import dataclass, field
from pathlib import Path

HERE = Path(__file__).resolve().parent
FMU = HERE / "GrainWorld.fmu"
#: a flow level this close to 0 or 1 is 0 or 1 (the ramp's float steps do not land on them exactly)
LEVEL_EPS = 1e-9


@dataclass
class Machines:
    """What the Simulink model knows of its machines (the scenario's values for the example)."""

    combine_speed_mps: float = 2.0
    flow_m3ps: float = 0.125
    spool_up_s: float = 1.0
    run_out_s: float = 1.0
    cart_length_m: float = 6.0
    cart_width_m: float = 3.0
    sections: int = 9
    target_m: float = 1.9
    tau_s: float = 1.0              # Machine Sync's longitudinal lag


@dataclass
class Tuning:
    """The controller's constants."""

    full_at: float = 0.975          # perceived fullness that closes a section
    on_tolerance_m: float = 0.25    # auger on while the predicted impact is this close to the section centre, m
    wall_margin_m: float = 0.3      # and at least this far inside the walls, m
    aim_margin_m: float = 0.4       # the aim point stays this far inside the front and rear walls, m
    max_rate_mps: float = 0.6       # setpoint rate limit, m/s
    drift_gain: float = 0.2         # low-pass gain of the measured drift per frame


@dataclass
class Result:
    """The run's record: time s, frames, every output per frame (name -> list), when every section was done."""

    t_s: float = 0.0
    frames: int = 0
    done_at_s: float = math.nan
    series: dict = field(default_factory=dict)
    final: dict = field(default_factory=dict)


def _rot(yaw: float, x: float, y: float) -> tuple[float, float]:
    c, s = math.cos(yaw), math.sin(yaw)
    return c * x - s * y, s * x + c * y


class Master:
    """The vehicle, auger and controller equations; :meth:`step` maps the FMU's outputs to its next inputs."""

    def __init__(self, start: dict[str, float], m: Machines, k: Tuning, period_s: float):
        self.m, self.k, self.T = m, k, period_s
        cx, cy, cyaw = start["combine_x_m"], start["combine_y_m"], start["combine_yaw_rad"]
        self.combine = [cx, cy, cyaw]
        #: offsets in the combine's frame (x forward, y left) of the cart, the tractor and the spout
        self.cart_off = list(_rot(-cyaw, start["cart_x_m"] - cx, start["cart_y_m"] - cy))
        self.tractor_off = _rot(-cyaw, start["tractor_x_m"] - start["cart_x_m"], start["tractor_y_m"] - start["cart_y_m"])
        self.spout_off = (*_rot(-cyaw, start["spout_x_m"] - cx, start["spout_y_m"] - cy), start["spout_z_m"])
        self.setpoint = self.cart_off[0]
        self.level, self.auger_on, self.drift = 0.0, False, 0.0
        self.full = [False] * m.sections

    def inputs(self) -> dict[str, float]:
        """The FMU's inputs at the current state."""
        cx, cy, yaw = self.combine
        ox, oy = _rot(yaw, *self.cart_off)
        kx, ky = cx + ox, cy + oy
        tx, ty = _rot(yaw, *self.tractor_off)
        sx, sy = _rot(yaw, *self.spout_off[:2])
        return {"combine_x_m": cx, "combine_y_m": cy, "combine_yaw_rad": yaw, "cart_x_m": kx, "cart_y_m": ky,
                "cart_yaw_rad": yaw, "tractor_x_m": kx + tx, "tractor_y_m": ky + ty, "tractor_yaw_rad": yaw,
                "spout_x_m": cx + sx, "spout_y_m": cy + sy, "spout_z_m": self.spout_off[2],
                "auger_on": self.auger_on, "flow_m3ps": self.m.flow_m3ps * self.level}

    def _spout_grid(self) -> tuple[float, float]:
        """The spout over the cart's grid (x from the front wall rearwards, y from the left wall), m."""
        bx, by = self.spout_off[0] - self.cart_off[0], self.spout_off[1] - self.cart_off[1]
        return self.m.cart_length_m / 2.0 - bx, self.m.cart_width_m / 2.0 - by

    def step(self, y: dict) -> bool:
        """Decide from the FMU's outputs ``y``, then advance the machines one frame; False once every section is
        done and the flow has run out."""
        m, k = self.m, self.k
        gx, gy = self._spout_grid()
        if y["perceived_impact_valid"] and self.level > 0.5:
            self.drift += k.drift_gain * (y["perceived_impact_gx_m"] - gx - self.drift)
        for i, f in enumerate(y["perceived_fullness"]):
            self.full[i] = self.full[i] or (f == f and f >= k.full_at)
        target = next((i for i, f in enumerate(self.full) if not f), None)
        if target is None:
            self.auger_on = False
        else:
            centre = (target + 0.5) * m.cart_length_m / m.sections
            aim = min(max(centre, k.aim_margin_m), m.cart_length_m - k.aim_margin_m)
            err = aim - (gx + self.drift)
            step = k.max_rate_mps * self.T
            self.setpoint += max(-step, min(step, err))
            inside = (k.wall_margin_m <= gx + self.drift <= m.cart_length_m - k.wall_margin_m and
                      k.wall_margin_m <= gy <= m.cart_width_m - k.wall_margin_m)
            self.auger_on = abs(err) <= k.on_tolerance_m and inside
        # the machines over the frame
        cx, cy, yaw = self.combine
        self.combine = [cx + m.combine_speed_mps * self.T * math.cos(yaw), cy + m.combine_speed_mps * self.T *
                        math.sin(yaw), yaw]
        self.cart_off[0] += (self.setpoint - self.cart_off[0]) * (1.0 - math.exp(-self.T / m.tau_s))
        ramp = m.spool_up_s if self.auger_on else -m.run_out_s
        level = self.level + self.T / ramp
        self.level = 1.0 if level > 1.0 - LEVEL_EPS else 0.0 if level < LEVEL_EPS else level
        return target is not None or self.level > 0.0


def run(fmu: Path = FMU, duration_s: float = 120.0, machines: Machines | None = None,
        tuning: Tuning | None = None) -> Result:
    """Drive the world FMU for up to ``duration_s`` s (it stops earlier once the cart is done); return the record."""
    import fmpy
    from fmpy.fmi2 import FMU2Slave
    from fmpy.model_description import read_model_description

    md = read_model_description(str(fmu))
    T = float(md.defaultExperiment.stepSize)
    var = {v.name: v for v in md.modelVariables}
    start = {v.name: float(v.start) for v in md.modelVariables if v.causality == "input" and v.type == "Real"}
    m = machines or Machines()
    master = Master(start, m, tuning or Tuning(), T)
    outs = [v for v in md.modelVariables if v.causality == "output"]
    unzipped = fmpy.extract(str(fmu))
    slave = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier,
                      instanceName="world")
    result = Result()
    try:
        slave.instantiate()
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        t, more = 0.0, True
        while more and t < duration_s - 1e-9:
            y = _read(slave, outs, m.sections)
            for name, value in y.items():
                result.series.setdefault(name, []).append(value)
            if math.isnan(result.done_at_s) and all(master.full):
                result.done_at_s = t
            more = master.step(y)
            for name, value in master.inputs().items():
                ref = [var[name].valueReference]
                (slave.setBoolean if isinstance(value, bool) else slave.setReal)(ref, [value])
            slave.doStep(currentCommunicationPoint=t, communicationStepSize=T)
            t += T
            result.frames += 1
        result.t_s, result.final = t, _read(slave, outs, m.sections)
        slave.terminate()
    finally:
        slave.freeInstance()
        shutil.rmtree(unzipped, ignore_errors=True)
    return result


def _read(slave, outs, sections: int) -> dict:
    """The FMU's outputs, per-section ones (``name[k]``) gathered into lists."""
    reals = [v for v in outs if v.type == "Real"]
    values = dict(zip((v.name for v in reals), slave.getReal([v.valueReference for v in reals])))
    for v in outs:
        if v.type == "Boolean":
            values[v.name] = bool(slave.getBoolean([v.valueReference])[0])
        elif v.type == "Integer":
            values[v.name] = slave.getInteger([v.valueReference])[0]
    y = {}
    for name, value in values.items():
        base, _, k = name.partition("[")
        if k:
            y.setdefault(base, [math.nan] * sections)[int(k[:-1]) - 1] = value
        else:
            y[name] = value
    return y


if __name__ == "__main__":
    quick = os.environ.get("GRAINCOSIM_EXAMPLE_QUICK") == "1"
    r = run(duration_s=3.0 if quick else 120.0)
    f = r.final
    print(f"{r.frames} frames ({r.t_s:.1f} s); every section done at {r.done_at_s:.1f} s; delivered "
          f"{f['delivered_m3']:.2f} m^3, in the cart {f['in_cart_m3']:.2f} m^3, spilled {f['spilled_m3']:.3f} m^3; "
          f"peak {f['peak_height_m']:.3f} m (target {Machines().target_m} m)")
    print("section mean heights, m:", " ".join(f"{h:.2f}" for h in f["true_mean_height_m"]))
