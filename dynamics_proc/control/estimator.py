"""The fused fill estimator: perceived heights fused with the volume known to have been delivered.

A per-cell Kalman filter on the controller grid (cart grid frame, heights m above the cart floor, cell (i, j)
centred at ((i + 0.5) c, (j + 0.5) c)). Each frame:

* **predict** (:func:`predict`): the volume the auger delivered during the frame (the machine's flow signal,
  m^3) is deposited at the impact point predicted from the known geometry (the ballistic landing on the
  estimated surface) with the grain fill model's heap law (:func:`dynamics_proc.grain.fill.deposit`: a
  flat-topped cone at the crop's angle of repose, volume exact). Each cell's variance grows by
  ``(flow_sigma * dh)^2`` (dh the cell's rise: flow, heap shape and placement uncertainty scale with it) plus
  ``settle_sigma_m^2`` (grain settles and slides in ways the heap law does not know);
* **update** (:func:`update`): every cell with a valid perceived height z is corrected with gain
  K = P / (P + R), R = ``measurement_sigma_m^2``. The measurement is L frames old (the feedback latency),
  so the innovation is taken against the estimate of that time: the estimate less the rises predicted
  since (:attr:`FillEstimate.pending`), and the correction is applied to the current estimate;
* **gate** (:func:`consistent`): before the update, each valid cell's innovation is normalised by its
  standard deviation sqrt(P + R); a map with more than ``gate_share`` of its cells beyond ``gate_sigma`` is
  rejected whole (a cart "found" in a dust cloud, a misregistered frame: the cells disagree everywhere at once,
  while grain the prediction misplaced disagrees in a few). A rejected map is no measurement.

Why it helps (the paper's degradation, its Fig 10b): the section being filled is the one the falling stream
hides and the spout's own geometry views at grazing angles, so a purely perceived peak lags or disappears
exactly where grain is arriving and the section overfills. The predicted rise does not need a view; perception
corrects the prediction wherever it sees, and the variance says how much to trust each.

Where it stops being valid: the heap law assumes grain settles at the angle of repose around the impact, with
no avalanching beyond its cone; a flow signal biased by ``b`` puts ``b`` of the delivered volume in the wrong
place until perception sees it (tests show the result with a 15 % biased flow signal); a cell never seen keeps
the level of its first-seen neighbours' median. The gate trusts the estimate: were the estimate itself wrong by
more than ``gate_sigma`` standard deviations over more than ``gate_share`` of the seen cells, every later map
would be rejected too; the variance then grows each frame (``settle_sigma_m``) until the gate widens enough to
let a map in, and meanwhile the controller's confidence rule (``controller.coping.fallback_sigma_m``) holds the
auger.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dynamics_proc.grain.auger import landing_xy
from dynamics_proc.grain.fill import GrainGrid, deposit

__all__ = ["FusionParams", "FillEstimate", "initial_estimate", "landing_on", "predict", "consistent", "update",
           "LANDING_ITERATIONS"]

#: fixed-point iterations of the landing on the estimated surface (each moves it by the surface slope times
#: the stream's horizontal drift per metre of fall; 4 settle it to millimetres on a heap at the repose angle)
LANDING_ITERATIONS = 4


@dataclass(frozen=True)
class FusionParams:
    """Constants of the fused estimator (SI). ``grid``: the controller grid as a grain grid (cell, depth,
    repose of the heap law); ``lag``: frames between a measurement and the estimate it corrects."""

    grid: GrainGrid
    flow_sigma: float
    settle_sigma_m: float
    measurement_sigma_m: float
    lag: int
    gate_sigma: float = float("inf")
    gate_share: float = 1.0

    @property
    def r(self) -> float:
        """Measurement variance R, m^2."""
        return self.measurement_sigma_m ** 2


@dataclass(frozen=True)
class FillEstimate:
    """Estimator state. ``height`` (nx, ny) m, NaN before the first measurement; ``var`` (nx, ny) m^2;
    ``pending``: the predicted rises (nx, ny) m of the last ``lag`` frames, oldest first."""

    height: np.ndarray
    var: np.ndarray
    pending: tuple[np.ndarray, ...]

    @property
    def started(self) -> bool:
        """A measurement has initialised the map."""
        return not bool(np.isnan(self.height[0, 0]))


def initial_estimate(p: FusionParams) -> FillEstimate:
    """Nothing known: NaN heights, infinite variance, no pending rises."""
    shape = (p.grid.nx, p.grid.ny)
    return FillEstimate(np.full(shape, np.nan), np.full(shape, np.inf), ())


def landing_on(h: np.ndarray, spout: np.ndarray, vel: np.ndarray, grid: GrainGrid,
               gravity: np.ndarray | None = None) -> tuple[float, float]:
    """Where the stream from ``spout`` (3,) m with exit velocity ``vel`` (3,) m/s (cart grid frame, gravity
    along -z) lands on the height map ``h`` (nx, ny) m: the fixed point of "land on the plane at the height of
    the cell below the landing point", started from the highest cell. Returns grid (x, y) m (may lie outside
    the grid: the stream then misses the cart). ``gravity`` (3,) m/s^2 in that frame on a tilted cart (None: -z)."""
    z = float(np.max(h))
    x = y = 0.0
    for _ in range(LANDING_ITERATIONS):
        x, y = landing_xy(spout, vel, z, gravity)
        i, j = int(x // grid.cell_m), int(y // grid.cell_m)
        if not (0 <= i < grid.nx and 0 <= j < grid.ny):
            break
        z = float(h[i, j])
    return x, y


def predict(e: FillEstimate, vol_m3: float, gx: float, gy: float, p: FusionParams) -> FillEstimate:
    """Deposit ``vol_m3`` (>= 0) at the predicted impact (gx, gy) (cart grid frame, m) and grow the variances.

    Before the first measurement there is nothing to deposit on: only the pending queue advances. Volume that
    the heap law spills over a wall top leaves the estimate, as it leaves the cart. Returns a new estimate."""
    rise = np.zeros_like(e.var)
    h, var = e.height, e.var
    if e.started:
        if vol_m3 > 0.0 and 0.0 <= gx <= p.grid.length_m and 0.0 <= gy <= p.grid.width_m:
            new, _ = deposit(h, gx, gy, vol_m3, p.grid)
            rise = new - h
            h = new
        var = var + (p.flow_sigma * rise) ** 2 + p.settle_sigma_m ** 2
    pending = (e.pending + (rise,))[-p.lag:] if p.lag > 0 else ()
    return FillEstimate(h, var, pending)


def _estimate_then(e: FillEstimate) -> np.ndarray:
    """The estimate of the time a ``lag`` frames old measurement was taken: today's less the rises since."""
    return e.height - sum(e.pending) if e.pending else e.height


def consistent(e: FillEstimate, z: np.ndarray, p: FusionParams) -> bool:
    """Whether the perceived map ``z`` (nx, ny) m (NaN: no return, ``p.lag`` frames old) agrees with the estimate:
    at most ``p.gate_share`` of its valid cells have an innovation beyond ``p.gate_sigma`` sqrt(P + R). Before the
    first map, and for a map with no valid cell, True (nothing to compare)."""
    z = np.asarray(z, dtype=np.float64)
    ok = ~np.isnan(z)
    if not e.started or not ok.any():
        return True
    innovation = np.abs(z[ok] - _estimate_then(e)[ok])
    outside = innovation > p.gate_sigma * np.sqrt(e.var[ok] + p.r)
    return float(np.count_nonzero(outside)) <= p.gate_share * innovation.size


def update(e: FillEstimate, z: np.ndarray, p: FusionParams) -> FillEstimate:
    """Correct with a perceived map ``z`` (nx, ny) m, NaN where no valid return, that is ``p.lag`` frames old.

    The first map with a valid cell initialises the estimate: seen cells take their value with variance R,
    unseen ones the median of the seen (variance: their spread plus R). Returns a new estimate."""
    z = np.asarray(z, dtype=np.float64)
    ok = ~np.isnan(z)
    if not ok.any():
        return e
    if not e.started:
        seen = z[ok]
        fill = float(np.median(seen))
        h = np.where(ok, z, fill)
        var = np.where(ok, p.r, float(np.var(seen)) + p.r)
        return FillEstimate(h, var, e.pending)
    then = _estimate_then(e)
    gain = np.where(ok, e.var / (e.var + p.r), 0.0)
    innovation = np.where(ok, z - then, 0.0)
    h = e.height + gain * innovation
    var = (1.0 - gain) * e.var
    return FillEstimate(h, var, e.pending)
