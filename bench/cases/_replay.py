"""A fixed workload for the perception process, independent of the machine's load and of the other processes:
the perception inputs of a run, recorded once, replayed through the participant.

:func:`record` runs a scenario in-process and keeps, for every ``every``-th frame (plus the ``offsets`` after it,
from ``start``), exactly what the perception participant reads: the depth images, ``dyn_state``,
``heightmap_truth`` and ``stream``, in one ``.npz`` with the resolved scenario. Frame ids are kept, so noise and the
accuracy sample are those of the run. :func:`replay_outputs` writes each recorded frame into a local segment and
runs ``PerceptionParticipant`` step + rest + flush (the overlapped participant, as in a run); :func:`compare`
compares two replays' outputs bit for bit.
"""
from __future__ import annotations

from pathlib import Path

__all__ = ["TRUTH_BLOCKS", "Recording", "compare", "load_inputs", "local_segment", "record", "replay_outputs"]

#: truth blocks the accuracy evaluation reads
TRUTH_BLOCKS = ("heightmap_truth", "stream")


def record(scenario, path: Path, every: int, offsets: tuple[int, ...], frames: int | None, start: int = 0) -> int:
    """Run ``scenario`` in-process and save the perception inputs of the kept frames to ``path``; returns how many
    frames were kept."""
    import numpy as np

    from cosim.runtime.files import atomic_replace
    from cosim.runtime.inprocess import simulate
    from perception_proc import participant as perc_mod

    kept: dict[str, list] = {"frame": [], "state": [], **{b: [] for b in TRUTH_BLOCKS}}
    images: dict[str, list] = {}
    base_create = perc_mod.create

    def create(sc):
        p = base_create(sc)
        step = p.step

        def recording_step(frame: int):
            if frame >= start and frame % every in offsets:
                seg = p.segment
                kept["frame"].append(frame)
                kept["state"].append(seg.view("dyn_state").as_dict())
                for b in TRUTH_BLOCKS:
                    kept[b].append(np.array(seg.view(b), copy=True))
                for name, img in p._images:
                    images.setdefault(name, []).append(np.array(img, copy=True))
            return step(frame)

        p.step = recording_step
        return p

    perc_mod.create = create                    # the ring resolves "perception_proc.participant:create" lazily
    try:
        simulate(scenario, frames=frames)
    finally:
        perc_mod.create = base_create
    names = list(kept["state"][0])
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_replace(path) as tmp, open(tmp, "wb") as f:
        np.savez_compressed(
            f, scenario=np.array(scenario.model_dump_json()), frames=np.array(kept["frame"], np.int64),
            state_names=np.array(names), state=np.array([[s[n] for n in names] for s in kept["state"]], np.float64),
            **{b: np.stack(kept[b]) for b in TRUTH_BLOCKS}, **{f"img_{k}": np.stack(v) for k, v in images.items()})
    return len(kept["frame"])


class Recording:
    """A recorded workload: ``scenario``, ``frames`` (F,) int64, per frame the ``dyn_state`` dict, the truth blocks
    and the depth images (H, W, 4) uint8 by block name."""

    def __init__(self, path: Path, limit: int | None = None):
        import numpy as np

        from cosim.scenario.config import Scenario

        z = np.load(path)
        self.scenario = Scenario.model_validate_json(str(z["scenario"]))
        n = len(z["frames"]) if limit is None else min(limit, len(z["frames"]))
        self.frames = z["frames"][:n]
        names = [str(s) for s in z["state_names"]]
        self.states = [dict(zip(names, row)) for row in z["state"][:n]]
        self.truth = {b: z[b][:n] for b in TRUTH_BLOCKS}
        self.images = {k[4:]: z[k][:n] for k in z.files if k.startswith("img_")}


def local_segment(scenario):
    """An in-process segment of ``scenario``'s whole schema."""
    from cosim.runtime.specs import build_schema, ring_specs
    from shm_schema import Segment

    return Segment.local(build_schema(scenario, ring_specs(scenario)))


def load_inputs(seg, rec: Recording, i: int) -> int:
    """Write recorded frame ``i`` into the segment's input blocks; returns its frame id."""
    frame = int(rec.frames[i])
    with seg.write("dyn_state", frame) as v:
        v.update(rec.states[i])
    for b in TRUTH_BLOCKS:
        with seg.write(b, frame) as v:
            v[...] = rec.truth[b][i]
    for name, imgs in rec.images.items():
        with seg.write(name, frame) as v:
            v[...] = imgs[i]
    return frame


def replay_outputs(rec: Recording) -> dict:
    """Every recorded frame through a fresh participant (step, rest, flush): ``state_names`` (S,), ``state`` (F, S)
    float64 (every ``perc_state`` field but the ``*_ms`` timings), ``heights`` (F, nx, ny) float32, ``points``
    (F, N, 4) float32."""
    import numpy as np

    from perception_proc.participant import PerceptionParticipant

    seg = local_segment(rec.scenario)
    part = PerceptionParticipant(rec.scenario)
    part.start(seg)
    names = [n for n in seg.view("perc_state").array.dtype.names if not n.endswith("_ms")]
    state, heights, points = [], [], []
    for i in range(len(rec.frames)):
        frame = load_inputs(seg, rec, i)
        rest = part.step(frame)
        if rest is not None:
            rest()
        part.flush()
        st = seg.view("perc_state").as_dict()
        state.append([st[n] for n in names])
        heights.append(np.array(seg.view("heightmap_perceived"), copy=True))
        points.append(np.array(seg.view("lidar_points"), copy=True))
    part.close()
    return {"state_names": np.array(names), "state": np.array(state, np.float64), "heights": np.stack(heights),
            "points": np.stack(points)}


def compare(out: dict, ref: dict) -> list[str]:
    """Differences between two :func:`replay_outputs` results, bit for bit (NaN equals NaN of the same bits);
    empty when identical."""
    import numpy as np

    problems = []
    names, ref_names = [str(s) for s in out["state_names"]], [str(s) for s in ref["state_names"]]
    if names != ref_names:
        return [f"perc_state fields differ: {sorted(set(names) ^ set(ref_names))}"]
    for key in ("state", "heights", "points"):
        a, b = out[key], ref[key]
        if a.shape != b.shape:
            problems.append(f"{key}: shape {a.shape} vs {b.shape}")
            continue
        diff = a.view(np.uint8).reshape(a.shape[0], -1) != b.view(np.uint8).reshape(b.shape[0], -1)
        bad = np.flatnonzero(diff.any(axis=1))
        if bad.size == 0:
            continue
        if key == "state":
            cols = np.flatnonzero((a != b) & ~(np.isnan(a) & np.isnan(b)))
            fields = sorted({names[c % len(names)] for c in cols})
            problems.append(f"state: {bad.size} frames differ, fields {fields}")
        else:
            with np.errstate(invalid="ignore"):
                worst = float(np.nanmax(np.abs(a.astype(np.float64) - b)))
            problems.append(f"{key}: {bad.size} frames differ (largest difference {worst:.3g} m)")
    return problems
