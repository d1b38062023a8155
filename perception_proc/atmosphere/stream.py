"""The grain stream as particles for the LiDAR: its kernels partly occlude the beams that cross it.

After Hahner et al. 2022 (snowfall on LiDAR point clouds): a beam of footprint diameter ``w(r) = divergence * r``
crossing a cloud of particles is split among the particles it meets and what lies behind them, by occlusion ratios
that sum to 1: the particles in range order each take the share of the still unoccluded beam that their disk
covers of the footprint (the exact circle-circle overlap area), the hard target behind gets the rest. Each
share returns like a Lambertian target at its range (perception_proc.atmosphere.dust.hard_power, times its share and the
transmission before it); the sensor reports the strongest or the last return above its detection limit.

The stream (the ``stream`` block: rows [x, y, z, radius] from the spout to the impact, equal times apart) holds
kernels of diameter d at the number density ``n = phi / (pi d^3 / 6)``, phi the solid fraction
``packing * flow / (speed * pi radius^2)`` (the flow's bulk volume through the drawn cross-section at the local
speed, from the rows' spacing). Along a beam's chord of length L through a segment of the stream, the kernels whose
disks overlap its footprint are a Poisson number of mean ``n pi ((w + d) / 2)^2 L``, uniform along the chord and
over that disk. Seeded per frame: ``SeedSequence(seed, spawn_key=(STREAM_PARTICLES, frame))``.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["STREAM_PARTICLES", "MAX_KERNELS", "ORDER_MIN_FRACTION_BITS", "beam_range_order", "disk_overlap",
           "kernel_share", "kernel_density", "occlude"]

#: the random stream of the kernels' draws (apart from the other seeded streams)
STREAM_PARTICLES = 3
#: at most this many kernels are drawn per crossing: a kernel takes about (d / w)^2 of a beam, so after 200 the
#: transmission through even the coarsest footprint (w = 3 mrad x 15 m) is below 1e-3
MAX_KERNELS = 200
#: the kernels' order by range keeps at least this many fractional bits of a metre (2^-20 m: a micrometre)
ORDER_MIN_FRACTION_BITS = 20


def disk_overlap(d: np.ndarray, r1: np.ndarray, r2: float | np.ndarray) -> np.ndarray:
    """Area (m^2) common to disks of radii ``r1`` and ``r2`` whose centres are ``d`` apart (arrays broadcast)."""
    d, r1, r2 = np.broadcast_arrays(np.asarray(d, np.float64), np.asarray(r1, np.float64), np.asarray(r2, np.float64))
    out = np.zeros(d.shape)
    inside = d <= np.abs(r1 - r2)
    out[inside] = math.pi * np.minimum(r1, r2)[inside] ** 2
    part = ~inside & (d < r1 + r2)
    if part.any():
        dd, a, b = d[part], r1[part], r2[part]
        c1 = np.clip((dd * dd + a * a - b * b) / (2 * dd * a), -1.0, 1.0)
        c2 = np.clip((dd * dd + b * b - a * a) / (2 * dd * b), -1.0, 1.0)
        k = (-dd + a + b) * (dd + a - b) * (dd - a + b) * (dd + a + b)
        out[part] = a * a * np.arccos(c1) + b * b * np.arccos(c2) - 0.5 * np.sqrt(np.maximum(k, 0.0))
    return out


def kernel_share(off: np.ndarray, kernel_d_m: float, w: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Share (M,) of its beam's footprint each kernel covers, at most 1: kernel m, ``off[m]`` m from the axis of
    crossing ``k[m]``, whose footprint is ``w`` (K,) m across. The same bits as the readable
    ``np.minimum(disk_overlap(off, kernel_d_m / 2, w[k] / 2) / (pi w[k]^2 / 4), 1)``, in fewer passes: the
    kernel's radius a scalar, what depends on the crossing alone made per crossing, the lens formula evaluated on
    every kernel and chosen by ``np.where`` (no masked copies)."""
    a, b_k = 0.5 * kernel_d_m, 0.5 * w
    b, bb = b_k[k], (b_k * b_k)[k]
    inside = off <= np.abs(a - b_k)[k]
    met = off < (a + b_k)[k]
    dd = off * off
    with np.errstate(divide="ignore", invalid="ignore"):
        c1 = np.clip((dd + a * a - bb) / (2 * off * a), -1.0, 1.0)
        c2 = np.clip((dd + bb - a * a) / (2 * off * b), -1.0, 1.0)
        q = (-off + a + b) * (off + a - b) * (off - a + b) * (off + a + b)
        lens = a * a * np.arccos(c1) + bb * np.arccos(c2) - 0.5 * np.sqrt(np.maximum(q, 0.0))
    area = np.where(inside, (math.pi * np.minimum(a, b_k) ** 2)[k], np.where(met, lens, 0.0))
    return np.minimum(area / (math.pi * 0.25 * w ** 2)[k], 1.0)


def kernel_density(rows: np.ndarray, flow_m3ps: float, packing: float, kernel_d_m: float,
                   dt_row_s: float) -> np.ndarray:
    """Kernels per m^3 (M - 1,) in each segment between ``rows`` (M, 4) (equal times ``dt_row_s`` apart): the
    bulk ``flow_m3ps`` times ``packing`` through each segment's cross-section at its speed (the rows' spacing
    over ``dt_row_s``), over one kernel's volume."""
    spacing = np.linalg.norm(np.diff(rows[:, :3].astype(np.float64), axis=0), axis=1)
    speed = np.maximum(spacing / dt_row_s, 1e-6)
    radius = 0.5 * (rows[:-1, 3] + rows[1:, 3]).astype(np.float64)
    area = math.pi * np.maximum(radius, 1e-9) ** 2
    phi = np.minimum(packing * flow_m3ps / (speed * area), packing)
    return phi / (math.pi * kernel_d_m ** 3 / 6.0)


def beam_range_order(beam: np.ndarray, r: np.ndarray, rank: np.ndarray | None = None) -> np.ndarray:
    """The permutation (M,) that sorts kernels by ``beam`` (M,) int, then by range ``r`` (M,) m: the order of
    ``np.lexsort((r, beam))``, found by one sort of int64 keys (a sort of values, several times faster than an
    argsort): each beam's rank in the top bits, ``r - min(r)`` in fixed point with :data:`ORDER_MIN_FRACTION_BITS`
    or more fractional bits below it (monotone in ``r``), the kernel's index in the lowest bits, read back from
    the sorted keys. Where two kernels of a beam share their fixed-point range (or the bits do not suffice, or a
    range is not finite) the order is left to ``np.lexsort`` itself. ``rank`` (M,) int64: the beams numbered
    0, 1, ... in their order (any numbering that keeps it; None: their rank among the beams present)."""
    n = beam.size
    if n == 0:
        return np.zeros(0, np.intp)
    if rank is None:
        present = np.zeros(int(beam.max()) + 1, np.int64)
        present[beam] = 1
        rank = np.take(np.cumsum(present) - 1, beam)                 # np.unique(beam, return_inverse=True)[1]
    lo, hi = float(r.min()), float(r.max())
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return np.lexsort((r, beam))
    index_bits, rank_bits = (n - 1).bit_length(), int(rank.max()).bit_length()
    whole_bits = math.ceil(math.log2(hi - lo + 1.0))
    fraction_bits = 63 - index_bits - rank_bits - whole_bits
    if fraction_bits < ORDER_MIN_FRACTION_BITS:
        return np.lexsort((r, beam))
    fixed = np.floor((r - lo) * 2.0 ** fraction_bits).astype(np.int64)   # < 2^(whole + fraction bits)
    key = (rank << (63 - rank_bits)) | (fixed << index_bits) | np.arange(n, dtype=np.int64)
    key.sort()
    head = key >> index_bits                                         # rank and fixed-point range
    if (head[1:] == head[:-1]).any():
        return np.lexsort((r, beam))
    return (key & ((1 << index_bits) - 1)).astype(np.intp)


def occlude(ranges: np.ndarray, beams: np.ndarray, mids: np.ndarray, chords: np.ndarray, density: np.ndarray,
            kernel_d_m: float, divergence_rad: float, rng: np.random.Generator):
    """The kernels the beams meet: crossing k (beam ``beams[k]``, chord of length ``chords[k]`` centred at range
    ``mids[k]`` m, ``density[k]`` kernels/m^3), with ``ranges`` (N,) the hard targets (NaN none). Returns
    (beams with kernels (B,) int64, per kernel: its beam's row in that list (M,), range (M,) m, share of the beam
    (M,); the share left for each beam's target (B,)), kernels in range order within a beam, the shares and what is
    left summing to 1 per beam."""
    w = divergence_rad * np.maximum(mids, 1e-3)
    reach = 0.5 * (w + kernel_d_m)
    counts = np.minimum(rng.poisson(density * math.pi * reach * reach * chords), MAX_KERNELS)
    k = np.repeat(np.arange(len(beams)), counts)
    r = (mids - 0.5 * chords)[k] + chords[k] * rng.random(k.size)
    off = reach[k] * np.sqrt(rng.random(k.size))                     # uniform over the disk of reach
    beam = beams[k]
    target = ranges[beam]
    front = np.flatnonzero(~(np.isfinite(target) & (r >= target)))  # kernels behind the target are never met
    k, beam, r, off = k[front], beam[front], r[front], off[front]
    share = kernel_share(off, kernel_d_m, w, k)
    order = beam_range_order(beam, r, np.unique(beams, return_inverse=True)[1].take(k))
    beam, r, share = beam[order], r[order], share[order]
    starts = np.concatenate([[True], beam[1:] != beam[:-1]]) if beam.size else np.zeros(0, bool)
    first = np.flatnonzero(starts)                                  # each beam's first kernel (beam is sorted)
    ids, row = beam[first], np.cumsum(starts) - 1                   # np.unique(beam, return_inverse=True)
    logs = np.log1p(-np.minimum(share, 1.0 - 1e-12))
    cum = np.cumsum(logs)
    start = np.concatenate([[0.0], cum])[first][row]                 # sum of the logs before each beam's first
    before = np.exp(np.concatenate([[0.0], cum[:-1]]) - start)       # transmission before each kernel
    took = before * share
    left = np.exp(np.add.reduceat(logs, first)) if len(ids) else np.zeros(0)
    return ids, row, r, took, left
