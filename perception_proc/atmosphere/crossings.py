"""Where the LiDAR's beams cross the grain stream (perception_proc.atmosphere.stream's particles lie along them).

The stream is a polyline of short segments (the ``stream`` block's rows [x, y, z, radius], world, m), each taken
as a cylinder of its rows' mean radius. A beam crosses a segment where its closest approach to the segment's axis
lies on the segment, ahead of the sensor and inside the radius (:func:`closest_approach`, the one exact test).

Culls choose the (beam, segment) pairs that take the exact test, and every cull below gives the same crossings
to the bit: a crossing's closest point lies inside its segment's bounding sphere by at least
``radius + L / 2 - sqrt(radius^2 + L^2 / 4)`` (L the segment's length; centimetres for the stream's segments), so
no cull that keeps every pair whose beam passes within a sphere around that one drops it; and a cull on the foot
of the closest approach along the axis that allows for more than the rounding between its arithmetic and the
exact test's keeps every pair whose foot the exact test finds on the segment.

* :func:`beam_crossings_reference`: every beam against the bounding sphere of each group of :data:`GROUP`
  segments, then against each segment's sphere (the readable form).
* :func:`beam_crossings`: every beam against one sphere around the whole stream (the stream fills a small part
  of the LiDAR's view: a few thousand of its tens of thousands of beams pass), those against every group's sphere
  at once, then each group's segments' spheres, then the foot; a tenth of the reference's pairs take the exact
  test. The crossings come in the reference's order (group, beam, segment), which the kernels' random draws
  follow.
"""
from __future__ import annotations

import numpy as np

__all__ = ["GROUP", "CULL_MARGIN_M", "FOOT_SLACK_M", "ROUNDING", "PARALLEL_DEN", "beam_crossings",
           "beam_crossings_reference", "closest_approach"]

#: segments per bounding sphere of the beam cull
GROUP = 8
#: the optimised cull's spheres are this much larger than the reference's (m): far below the stream's margin
#: (module docstring), far above the rounding of the cull's arithmetic
CULL_MARGIN_M = 1e-6
#: the foot of a beam's closest approach may lie this far off its segment (m) and still be tested exactly ...
FOOT_SLACK_M = 1e-6
#: ... plus this times the magnitudes it is made of over ``1 - cos^2``: a bound, with a wide margin, of the
#: difference between the cull's rounding (matrix products) and the exact test's (``np.einsum``)
ROUNDING = 1e-12
#: ``1 - cos^2`` of a beam and an axis at or below which the foot is not computed (the pair is tested exactly;
#: the exact test drops those at or below 1e-12)
PARALLEL_DEN = 1e-9


def _segments(rows: np.ndarray) -> tuple[np.ndarray, ...]:
    """The stream's segments of non-zero length between consecutive ``rows`` (M, 4): start (S, 3), unit axis
    (S, 3), length (S,), radius (S,), bounding sphere's centre (S, 3) and radius (S,) (m), index among the M - 1
    segments (S,)."""
    p0, p1 = rows[:-1, :3].astype(np.float64), rows[1:, :3].astype(np.float64)
    radius = 0.5 * (rows[:-1, 3] + rows[1:, 3]).astype(np.float64)
    axis = p1 - p0
    length = np.linalg.norm(axis, axis=1)
    keep = length > 0.0
    p0, axis, length, radius = p0[keep], axis[keep], length[keep], radius[keep]
    u = axis / length[:, None]
    mid = p0 + 0.5 * axis
    return p0, u, length, radius, mid, 0.5 * length + radius, np.flatnonzero(keep)


def _sphere_cull(origin: np.ndarray, directions: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Indices (C,) of the ``directions`` (N, 3) whose beams from ``origin`` pass through the sphere around the
    box [``lo``, ``hi``] (3,) m (its half diagonal the radius), ahead of the sensor or within that radius behind."""
    return _ball_cull(directions, 0.5 * (lo + hi) - origin, 0.5 * float(np.linalg.norm(hi - lo)))


def _ball_cull(directions: np.ndarray, to_c: np.ndarray, rad: float) -> np.ndarray:
    """Indices (C,) of the ``directions`` (N, 3) whose beams pass through the sphere of radius ``rad`` m centred
    ``to_c`` (3,) m from their origin (in the directions' frame), ahead or within that radius behind."""
    along = directions @ to_c
    return np.flatnonzero((along > -rad) & (float(to_c @ to_c) - along * along <= rad * rad))


def _near(directions: np.ndarray, to_m: np.ndarray, seg_r: np.ndarray) -> np.ndarray:
    """(C, G) whether each of ``directions`` (C, 3) passes within ``seg_r`` (G,) m of the spheres' centres
    ``to_m`` (G, 3) (from the origin), not behind by more than that."""
    a_m = directions @ to_m.T
    return (a_m > -seg_r[None, :]) & (np.einsum("sk,sk->s", to_m, to_m)[None, :] - a_m * a_m <= seg_r[None, :] ** 2)


def closest_approach(origin: np.ndarray, directions: np.ndarray, beam_of: np.ndarray, si: np.ndarray,
                     segments: tuple[np.ndarray, ...]) -> tuple[np.ndarray, ...]:
    """The exact test of the candidate pairs (beam ``beam_of`` (K,), segment ``si`` (K,) of ``segments``, from
    :func:`_segments`): the crossings among them as in :func:`beam_crossings_reference`'s return."""
    p0, u, length, radius, _, _, seg_ids = segments
    d, w0, us = directions.take(beam_of, axis=0), origin[None, :] - p0.take(si, axis=0), u.take(si, axis=0)
    b = np.einsum("kj,kj->k", d, us)                                 # cos of the angle between them
    dd = np.einsum("kj,kj->k", d, w0)
    e = np.einsum("kj,kj->k", us, w0)
    den = 1.0 - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        t_beam = (b * e - dd) / den                                  # closest point: along the beam
        t_seg = (e - b * dd) / den                                   # along the segment's axis
    dist = np.linalg.norm(w0 + t_beam[:, None] * d - t_seg[:, None] * us, axis=1)
    hit = (den > 1e-12) & (t_beam > 0.0) & (t_seg >= 0.0) & (t_seg <= length[si]) & (dist < radius[si])
    beam_of, si, t_beam, dist, den = beam_of[hit], si[hit], t_beam[hit], dist[hit], den[hit]
    sin_a = np.sqrt(den)
    chord = 2.0 * np.sqrt(radius[si] ** 2 - dist ** 2) / sin_a
    return beam_of, seg_ids[si], t_beam, np.minimum(chord, length[si] / sin_a + 2.0 * radius[si])


def _empty() -> tuple[np.ndarray, ...]:
    return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), np.zeros(0)


def beam_crossings_reference(origin: np.ndarray, directions: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, ...]:
    """Where beams from ``origin`` (3,) along unit ``directions`` (N, 3) (world) cross the stream's segments
    between consecutive ``rows`` (M, 4) [x, y, z, radius] (world, m): (beam index (K,), segment index (K,),
    range of the crossing's middle (K,) m, chord length (K,) m), in the order group, beam, segment."""
    segments = _segments(rows)
    p0, mid, seg_r = segments[0], segments[4], segments[5]
    to_m = mid - origin                                              # (S, 3)
    pairs_b, pairs_s = [], []
    for g0 in range(0, len(p0), GROUP):
        g = slice(g0, g0 + GROUP)
        cand = _sphere_cull(origin, directions, (mid[g] - seg_r[g, None]).min(0), (mid[g] + seg_r[g, None]).max(0))
        if cand.size == 0:
            continue
        ci, si = np.nonzero(_near(directions[cand], to_m[g], seg_r[g]))
        pairs_b.append(cand[ci])
        pairs_s.append(si + g0)
    if not pairs_b or sum(p.size for p in pairs_b) == 0:
        return _empty()
    return closest_approach(origin, directions, np.concatenate(pairs_b), np.concatenate(pairs_s), segments)


def _on_segment(origin: np.ndarray, d: np.ndarray, si: np.ndarray, segments: tuple[np.ndarray, ...]) -> np.ndarray:
    """(P,) whether the closest approach of beams ``d`` (3, P) (columns) to the axes of segments ``si`` (P,) may
    lie on the segment: its foot along the axis, by plain column arithmetic (rounded unlike
    :func:`closest_approach`'s ``np.einsum``), within :data:`FOOT_SLACK_M` plus its rounding's bound of the
    segment, or the beam too near parallel to the axis to tell."""
    w0_all = origin[None, :] - segments[0]
    u, w0 = np.ascontiguousarray(segments[1].T).take(si, axis=1), np.ascontiguousarray(w0_all.T).take(si, axis=1)
    e = np.einsum("sk,sk->s", segments[1], w0_all).take(si)
    b = d[0] * u[0] + d[1] * u[1] + d[2] * u[2]
    dd = d[0] * w0[0] + d[1] * w0[1] + d[2] * w0[2]
    den = 1.0 - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        t_seg = (e - b * dd) / den
        slack = FOOT_SLACK_M + ROUNDING * (np.abs(e) + np.abs(dd) + np.abs(t_seg)) / den
    return (den <= PARALLEL_DEN) | ((t_seg >= -slack) & (t_seg <= segments[2].take(si) + slack))


def _group_pairs(origin: np.ndarray, d_c: np.ndarray, mid: np.ndarray, seg_r: np.ndarray, lo: np.ndarray,
                 hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(beam (P,) of ``d_c`` (C, 3), segment (P,)) pairs that pass both culls of the reference, all groups'
    spheres tested at once, in the reference's order (group, beam, segment)."""
    starts = np.arange(0, len(mid), GROUP)
    g_lo, g_hi = np.minimum.reduceat(lo, starts, axis=0), np.maximum.reduceat(hi, starts, axis=0)
    to_c, rad = 0.5 * (g_lo + g_hi) - origin, 0.5 * np.linalg.norm(g_hi - g_lo, axis=1)
    along = to_c @ d_c.T                                             # (NG, C)
    in_group = (along > -rad[:, None]) & (np.einsum("gk,gk->g", to_c, to_c)[:, None] - along * along
                                          <= (rad * rad)[:, None])
    to_m = mid - origin
    tm2, r2 = np.einsum("sk,sk->s", to_m, to_m), seg_r * seg_r
    pairs_b, pairs_s = [], []
    for gi, g0 in enumerate(starts):
        sub = np.flatnonzero(in_group[gi])
        g = slice(g0, g0 + GROUP)
        a_m = d_c.take(sub, axis=0) @ to_m[g].T                      # (C_g, G)
        ci, si = np.nonzero((a_m > -seg_r[g]) & (tm2[g] - a_m * a_m <= r2[g]))
        pairs_b.append(sub[ci])
        pairs_s.append(si + g0)
    return np.concatenate(pairs_b), np.concatenate(pairs_s)


def beam_crossings(origin: np.ndarray, directions: np.ndarray, rows: np.ndarray,
                   rotation: np.ndarray | None = None) -> tuple[np.ndarray, ...]:
    """:func:`beam_crossings_reference` (the same bits) for unit ``directions`` (N, 3) in the frame that the
    orthonormal ``rotation`` (3, 3) turns into the world's (None: world directions), the reference's directions
    being ``directions @ rotation.T``: every beam tested once against a sphere around the whole stream (in the
    directions' own frame, so only the few beams that pass are turned into the world's: the same rows of the
    product), those against the groups and segments (spheres :data:`CULL_MARGIN_M` larger, :func:`_group_pairs`),
    and of those pairs only the ones whose closest approach may lie on the segment (:func:`_on_segment`) given the
    exact test, in the reference's order."""
    segments = _segments(rows)
    mid, seg_r = segments[4], segments[5]
    if len(mid) == 0:
        return _empty()
    seg_r = seg_r + CULL_MARGIN_M
    lo, hi = mid - seg_r[:, None], mid + seg_r[:, None]
    if rotation is None:
        cand = _sphere_cull(origin, directions, lo.min(0), hi.max(0))
        d_c = directions.take(cand, axis=0)
    else:                                                            # the sphere's centre into the beams' frame
        rad = 0.5 * float(np.linalg.norm(hi.max(0) - lo.min(0))) + CULL_MARGIN_M
        cand = _ball_cull(directions, rotation.T @ (0.5 * (lo.min(0) + hi.max(0)) - origin), rad)
        d_c = directions.take(cand, axis=0) @ rotation.T
    if cand.size == 0:
        return _empty()
    ci, si = _group_pairs(origin, d_c, mid, seg_r, lo, hi)
    on = np.flatnonzero(_on_segment(origin, np.ascontiguousarray(d_c.T).take(ci, axis=1), si, segments))
    if on.size == 0:
        return _empty()
    beam_of, seg, t_beam, chord = closest_approach(origin, d_c, ci.take(on), si.take(on), segments)
    return cand.take(beam_of), seg, t_beam, chord
