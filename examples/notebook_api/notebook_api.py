# %% [markdown]
# # Driving a run from Python
#
# A notebook-style script (`# %%` cells: open it in Jupyter with jupytext, in VS Code or in Spyder, or run it
# whole with `python examples/notebook_api/notebook_api.py`). It steps the default scenario, moves the cart
# sideways mid-run through Machine Sync's lateral offset, lowers the target fill, reads the state as it goes
# and plots what happened. The API is described in docs/api.md.
#
# `GRAINCOSIM_EXAMPLE_QUICK=1` shortens it (CI); `GRAINCOSIM_EXAMPLE_OUT` says where the figure goes
# (default `runs/notebook_api`).

# %%
import math
import os
from pathlib import Path

import numpy as np

from cosim import Simulation

QUICK = os.environ.get("GRAINCOSIM_EXAMPLE_QUICK") == "1"
OUT = Path(os.environ.get("GRAINCOSIM_EXAMPLE_OUT", "runs/notebook_api"))
HERE = Path(__file__).parent if "__file__" in globals() else Path("examples/notebook_api")  # a notebook has none
DURATION_S = 20.0 if QUICK else 120.0
MOVE_AT_S, LOWER_AT_S = 3.0, 15.0      # when the lateral offset moves, when the target is lowered
LATERAL_STEP_M = 0.3                    # the cart moves this much further left
LOW_TARGET_M = 1.6                      # the new target fill height

# the folder's scenario: the default one with ideal feedback (ground truth) and no renderer, so a whole 120 s run
# takes a second or two. For perception in the loop add feedback="perception", renderer="mock" (no OpenGL) or "gl".
sim = Simulation(HERE / "scenario.yaml", duration=DURATION_S)
obs = sim.reset()
print(f"frame {obs.frame}: t = {obs['dyn_state.t_s']:.1f} s, cart lateral setpoint "
      f"{obs['dyn_state.setpoint_lat_m']:.2f} m, {len(obs)} values in the state")

# %% step to the first change, keeping what we want to plot
period = sim.scenario.timing.sensor_period_s
lat0 = sim.scenario.machine_sync.lateral_offset_m
rows = []


def keep(o):
    """One row per frame: time s, the tractor's and the cart's lateral offsets from the combine m (world y: the
    combine drives straight along x)."""
    rows.append((o["dyn_state.t_s"], o["dyn_state.tractor_y_m"] - o["dyn_state.combine_y_m"],
                 o["dyn_state.cart_y_m"] - o["dyn_state.combine_y_m"]))


keep(obs)
while sim.time_s < MOVE_AT_S - 1e-9:
    keep(sim.step())
print(f"t = {sim.time_s:.1f} s: auger {'on' if sim.state['dyn_state.auger_on'] else 'off'}, "
      f"{sim.state['dyn_state.cart_grain_m3']:.2f} m^3 in the cart")

# %% move the cart sideways: Machine Sync follows with its lag
sim.set("machine_sync.lateral_offset_m", lat0 + LATERAL_STEP_M)
while sim.time_s < LOWER_AT_S - 1e-9:
    keep(sim.step())
t, tractor, cart = (np.array(c) for c in zip(*rows))
print(f"lateral offset {lat0:.2f} -> {lat0 + LATERAL_STEP_M:.2f} m at t = {MOVE_AT_S:.1f} s")
for name, lat in (("tractor", tractor), ("cart", cart)):
    off = (t > MOVE_AT_S) & (np.abs(lat - (lat0 + LATERAL_STEP_M)) > 0.1 * LATERAL_STEP_M)
    settled = t[off][-1] + period - MOVE_AT_S if off.any() else 0.0
    print(f"  {name}: within 10 % of the step {settled:.1f} s after it, overshoot "
          f"{max(0.0, lat[t > MOVE_AT_S].max() - lat0 - LATERAL_STEP_M) * 100:.1f} cm")

# %% lower the target fill and run to the end
sim.set("controller.target_fill_m", LOW_TARGET_M)
while not sim.done:
    sim.step(50)                       # 5 s at a time; the result keeps every frame
result = sim.result
sim.close()
fill = result.summary["fill"]
print(f"run done at t = {result.timeseries['dyn_state.t_s'][-1]:.1f} s: fill {fill['fill_fraction'] * 100:.1f} %, "
      f"target {fill['target_height_m']:.2f} m, time to target "
      + (f"{fill['time_to_target_s']:.1f} s" if not math.isnan(fill['time_to_target_s'] or math.nan) else "not reached"))
for c in result.summary["inputs_changed"]:
    print(f"  set at frame {c['frame']} (t = {c['t_s']:.1f} s): {c['path']} = {c['value']:g}")

# %% plot the whole run from the result's timeseries (every frame, not only the ones kept above)
import matplotlib  # noqa: E402  (a notebook cell imports what it plots with)

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

ts = result.timeseries
fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
ax1.plot(ts["dyn_state.t_s"], ts["dyn_state.tractor_y_m"] - ts["dyn_state.combine_y_m"], label="tractor")
ax1.plot(ts["dyn_state.t_s"], ts["dyn_state.cart_y_m"] - ts["dyn_state.combine_y_m"], label="cart")
ax1.plot(ts["dyn_state.t_s"], ts["dyn_state.setpoint_lat_m"], "--", label="setpoint")
ax1.set_ylabel("lateral offset (m)")
ax1.legend()
ax2.plot(ts["dyn_state.t_s"], ts["dyn_state.peak_height_m"], label="peak grain height")
ax2.plot(ts["dyn_state.t_s"], ts["dyn_state.target_fill_m"], "--", label="target")
ax2.set_xlabel("time (s)")
ax2.set_ylabel("height (m)")
ax2.legend()
OUT.mkdir(parents=True, exist_ok=True)
fig.savefig(OUT / "notebook_api.png", dpi=80)
print(f"figure: {OUT / 'notebook_api.png'}")
