"""Replay recorded perception inputs: per-stage cost (wall or callgrind instructions) and a bit-identity check.

A fixed workload for the perception process, independent of the machine's load and of the other processes:

* ``record``: runs a scenario in-process (default: ``default`` with its GL renderer; ``--renderer mock`` with
  ``render.mock_scale`` 1.0 writes the same bytes) and keeps, for every ``--every``-th frame (plus the
  ``--offsets`` after it, from ``--start``), exactly what the perception participant reads: the rig's depth
  images, ``dyn_state``, ``heightmap_truth`` and ``stream``. Written to one ``.npz`` (with the resolved
  scenario). Frame ids are kept, so noise and the accuracy sample are those of the run.
* ``replay``: writes each recorded frame into a local segment and runs ``PerceptionParticipant`` step + rest +
  flush (the overlapped participant, as in a run), keeping ``perc_state`` (every field but the ``*_ms``
  timings), ``heightmap_perceived`` and ``lidar_points``. ``--save`` writes them; ``--check`` compares them
  bit for bit with a saved reference (exit status 1 on any difference). Then the stages one by one over all
  frames (``--stages``), each after one unmetered warm-up call: lidar (resample + noise), points (the
  lidar_points record), level (level points and border flags), cart, heightmap, impact, accuracy (the
  evaluated frames), and the whole participant step (the harness's copying of the inputs into the segment
  left out). A frame is evaluated when the scenario's ``accuracy_every_frames`` divides its id.
* ``--callgrind``: under ``valgrind --tool=callgrind --collect-atstart=no`` each stage's loop is collected alone
  and dumped under its name (a small client-request library is compiled on first use into ``bench/out``);
  ``python bench/perception_replay.py totals callgrind.out.PID.*`` then prints instructions per stage and call;
  ``--focus STAGE:MODULE:FUNCTION`` (or ``MODULE:Class.method``) adds the inclusive count of one function
  within a stage (the function is wrapped where the stage looks it up: a module attribute).

Workloads used for the figures in the issue notes (bench/out is not tracked; re-record them):

    python bench/perception_replay.py record --out bench/out/replay/default.npz          # 121 frames, whole run
    python bench/perception_replay.py record --out bench/out/replay/consecutive800.npz --frames 860 \
        --start 800 --every 1 --offsets 0                                                # 61 consecutive frames

Run from the repository root (the thread pools are single-threaded here, as in a run's processes:
``cosim.runtime.threadpools``), e.g.::

    python bench/perception_replay.py replay bench/out/replay/default.npz --save bench/out/replay/ref.npz
    python bench/perception_replay.py replay bench/out/replay/default.npz --check bench/out/replay/ref.npz --stages
    PYTHONHASHSEED=0 valgrind --tool=callgrind --collect-atstart=no --callgrind-out-file=bench/out/cg.%p \
        python bench/perception_replay.py replay bench/out/replay/default.npz --stages --callgrind --limit 30
    python bench/perception_replay.py totals bench/out/cg.*.* --calls CALLS.json   # the JSON line printed above

Under valgrind run the interpreter itself (``python -c "import sys; print(sys.executable)"``), not a shell
shim: valgrind does not follow children. Callgrind counts each iteration of ``rep movsb``/``rep stosb`` as an
instruction, so large ``memcpy``/``memset`` (BLAS zeroing its output, copies of whole blocks) weigh far more
in its counts than in time.
"""
from __future__ import annotations

import argparse
import ctypes
import json
import re
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cosim.runtime.threadpools import default_to_single_threaded_pools  # noqa: E402

default_to_single_threaded_pools()      # before numpy and cv2 load: one-thread pools, as in a run's processes

import numpy as np  # noqa: E402

from cosim.scenario.config import Scenario  # noqa: E402
from cosim.scenario.loader import load_scenario, resolve_scenario_arg  # noqa: E402

#: stages timed or counted one by one, in pipeline order
STAGES = ("lidar", "points", "level", "cart", "heightmap", "impact", "accuracy", "step")
#: truth blocks the accuracy evaluation reads
TRUTH_BLOCKS = ("heightmap_truth", "stream")
_CG_SOURCE = """#include <valgrind/callgrind.h>
void cg_toggle(void) { CALLGRIND_TOGGLE_COLLECT; }
void cg_dump(const char *name) { CALLGRIND_DUMP_STATS_AT(name); }
void cg_zero(void) { CALLGRIND_ZERO_STATS; }
"""


# -- recording ---------------------------------------------------------------------------------------------------
def record(scenario: Scenario, path: Path, every: int, offsets: tuple[int, ...], frames: int | None,
           start: int = 0) -> int:
    """Run ``scenario`` in-process and save the perception inputs of the kept frames (from frame ``start``) to
    ``path``; returns how many frames were kept."""
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
    np.savez_compressed(
        path, scenario=np.array(scenario.model_dump_json()), frames=np.array(kept["frame"], np.int64),
        state_names=np.array(names), state=np.array([[s[n] for n in names] for s in kept["state"]], np.float64),
        **{b: np.stack(kept[b]) for b in TRUTH_BLOCKS}, **{f"img_{k}": np.stack(v) for k, v in images.items()})
    return len(kept["frame"])


class Recording:
    """A recorded workload: ``scenario``, ``frames`` (F,) int64, per frame the ``dyn_state`` dict, the truth blocks
    and the depth images by block name."""

    def __init__(self, path: Path, limit: int | None = None):
        z = np.load(path)
        self.scenario = Scenario.model_validate_json(str(z["scenario"]))
        n = len(z["frames"]) if limit is None else min(limit, len(z["frames"]))
        self.frames = z["frames"][:n]
        names = [str(s) for s in z["state_names"]]
        self.states = [dict(zip(names, row)) for row in z["state"][:n]]
        self.truth = {b: z[b][:n] for b in TRUTH_BLOCKS}
        self.images = {k[4:]: z[k][:n] for k in z.files if k.startswith("img_")}


# -- replay ------------------------------------------------------------------------------------------------------
def _segment(scenario: Scenario):
    from cosim.runtime.specs import build_schema, ring_specs
    from shm_schema import Segment

    return Segment.local(build_schema(scenario, ring_specs(scenario)))


def _load_inputs(seg, rec: Recording, i: int) -> int:
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


def _is_timing(name: str) -> bool:
    return name.endswith("_ms")


def replay_outputs(rec: Recording) -> dict[str, np.ndarray]:
    """Every recorded frame through a fresh participant (step, rest, flush): ``state_names`` (S,), ``state``
    (F, S) float64 (every ``perc_state`` field but the timings), ``heights`` (F, nx, ny) float32, ``points``
    (F, N, 4) float32."""
    from perception_proc.participant import PerceptionParticipant

    seg = _segment(rec.scenario)
    part = PerceptionParticipant(rec.scenario)
    part.start(seg)
    names = [n for n in seg.view("perc_state").array.dtype.names if not _is_timing(n)]
    state, heights, points = [], [], []
    for i in range(len(rec.frames)):
        frame = _load_inputs(seg, rec, i)
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


def compare(out: dict[str, np.ndarray], ref: dict[str, np.ndarray]) -> list[str]:
    """Differences between two :func:`replay_outputs` results, bit for bit (NaN equals NaN of the same bits);
    empty when identical."""
    problems = []
    names, ref_names = [str(s) for s in out["state_names"]], [str(s) for s in ref["state_names"]]
    if names != ref_names:
        problems.append(f"perc_state fields differ: {sorted(set(names) ^ set(ref_names))}")
        return problems
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


# -- stages ------------------------------------------------------------------------------------------------------
class _Callgrind:
    """Callgrind client requests through a tiny compiled library (``bench/out/cgreq.so``)."""

    def __init__(self):
        lib = ROOT / "bench" / "out" / "cgreq.so"
        if not lib.exists():
            src = lib.with_suffix(".c")
            lib.parent.mkdir(parents=True, exist_ok=True)
            src.write_text(_CG_SOURCE)
            subprocess.run(["cc", "-O1", "-shared", "-fPIC", "-o", str(lib), str(src)], check=True)
        self.lib = ctypes.CDLL(str(lib))

    active = False

    @contextmanager
    def collect(self, name: str) -> Iterator[None]:
        self.lib.cg_zero()
        self.lib.cg_toggle()
        self.active = True
        try:
            yield
        finally:
            self.active = False
            self.lib.cg_toggle()
            self.lib.cg_dump(name.encode())

    @contextmanager
    def exclude(self) -> Iterator[None]:
        """Not collected (inside :meth:`collect`; a no-op outside)."""
        if not self.active:
            yield
            return
        self.lib.cg_toggle()
        try:
            yield
        finally:
            self.lib.cg_toggle()


class _NoExclude:
    @contextmanager
    def exclude(self) -> Iterator[None]:
        yield


class _Focus(_NoExclude):
    """Callgrind collection only inside ``module:function`` while stage ``stage`` runs (inclusive instructions
    of that function, dumped as ``stage/module:function``); other stages are not collected."""

    def __init__(self, cg: _Callgrind, spec: str):
        self.cg = cg
        self.stage, _, self.target = spec.partition(":")
        self.module, _, self.function = self.target.partition(":")

    @contextmanager
    def collect(self, name: str) -> Iterator[None]:
        if name != self.stage:
            yield
            return
        import functools
        import importlib

        mod = importlib.import_module(self.module)
        *owners, attr = self.function.split(".")          # a function, or a class's method: "Class.method"
        for o in owners:
            mod = getattr(mod, o)
        fn = getattr(mod, attr)
        depth = [0]
        lib = self.cg.lib

        @functools.wraps(fn)
        def wrapped(*args, **kwargs):
            depth[0] += 1
            if depth[0] == 1:
                lib.cg_toggle()
            try:
                return fn(*args, **kwargs)
            finally:
                if depth[0] == 1:
                    lib.cg_toggle()
                depth[0] -= 1

        setattr(mod, attr, wrapped)
        lib.cg_zero()
        try:
            yield
        finally:
            setattr(mod, attr, fn)
            lib.cg_dump(f"{self.stage}/{self.target}".encode())


class _Clock:
    """Wall time per stage (``time.perf_counter``) and process CPU time."""

    def __init__(self):
        self.rows: dict[str, tuple[float, float]] = {}
        self._excluded = [0.0, 0.0]

    @contextmanager
    def collect(self, name: str) -> Iterator[None]:
        self._excluded = [0.0, 0.0]
        w, c = time.perf_counter(), time.process_time()
        try:
            yield
        finally:
            self.rows[name] = (time.perf_counter() - w - self._excluded[0],
                               time.process_time() - c - self._excluded[1])

    @contextmanager
    def exclude(self) -> Iterator[None]:
        """Not counted (inside :meth:`collect`)."""
        w, c = time.perf_counter(), time.process_time()
        try:
            yield
        finally:
            self._excluded[0] += time.perf_counter() - w
            self._excluded[1] += time.process_time() - c


def run_stages(rec: Recording, meter, repeat: int = 1, upto: str | None = None) -> dict[str, int]:
    """Each stage over every recorded frame (``repeat`` times), in frame order, after one call outside the
    meter (first-call costs: lazy imports, caches); the inputs of later stages are computed outside the meter
    as well. Stages after ``upto`` are left out. Returns the number of metered calls per stage."""
    from perception_proc import accuracy as acc
    from perception_proc import impact as impact_module  # looked up per call: --focus can wrap them
    from perception_proc.heightmap import height_map
    from perception_proc.participant import PerceptionParticipant
    from perception_proc.rim import border_beams, find_cart

    seg = _segment(rec.scenario)
    part = PerceptionParticipant(rec.scenario)
    part.start(seg)
    pipe, sc = part.pipeline, rec.scenario
    sigma = sc.sensor.noise.range_sigma_m
    frames = [int(f) for f in rec.frames]
    gathered = [pipe.gather([rec.images[name][i] for name, _ in part._images]) for i in range(len(frames))]
    headings = [part._heading(st, acc.world_from_parent(sc, st)) for st in rec.states]
    out: dict[str, dict] = {}

    def lidar(i):
        return pipe.noisy(pipe.resample_gathered(gathered[i]), frames[i])

    def level(i):
        r = out["lidar"][i]
        return pipe.level_points(r), border_beams(r, pipe.shape)

    def cart(i):
        p, b = out["level"][i]
        return find_cart(p, b, sc.cart, headings[i], sigma)

    def heightmap(i):
        return height_map(out["level"][i][0], out["cart"][i].level_from_grid, sc.cart, sc.controller.grid_cell_m,
                          sc.perception.min_points_per_cell, sigma)

    def impact(i):
        lfg, hm = out["cart"][i].level_from_grid, out["heightmap"][i]
        sg = (pipe.level_from_sensor[:3, 3] - lfg[:3, 3]) @ lfg[:3, :3]
        heights = hm.heights.copy()
        imp = impact_module.find_impact(hm.grid_points, hm.stream, heights, pipe.cell_xy,
                                        sc.perception.impact_search_radius_m, (float(sg[0]), float(sg[1])))
        impact_module.blank_under_stream(heights, imp, pipe.cell_xy)
        return imp

    clean = {}

    def accuracy(i):
        # the participant's evaluation of the frame (its seeded beam sample), on the frame's perception
        st, beams = rec.states[i], part._accuracy_beams(frames[i])
        res = out["perceived"][i]
        return part._accuracy(st, beams, clean[i][beams], res, acc.world_from_parent(sc, st),
                              part.pipeline.level_from_sensor, rec.truth["heightmap_truth"][i], rec.truth["stream"][i])

    def step(i):
        # the whole participant: step, rest, flush (accuracy included on the evaluated frames); writing the
        # recorded inputs into the segment is not counted
        with meter.exclude():
            _load_inputs(seg, rec, i)
        rest = part.step(frames[i])
        if rest is not None:
            rest()
        part.flush()

    everything = list(range(len(frames)))
    stages = {"lidar": (lidar, everything), "points": (lambda i: pipe.points(out["lidar"][i]), everything),
              "level": (level, everything), "cart": (cart, everything)}
    calls: dict[str, int] = {}
    for name in STAGES:
        if name == "heightmap":
            with_cart = [i for i in everything if out["cart"][i].valid]
            stages["heightmap"] = (heightmap, with_cart)
            stages["impact"] = (impact, with_cart)
        elif name == "accuracy":
            evaluated = [i for i in everything if part._accuracy_beams(frames[i]) is not None]
            out["perceived"] = {i: pipe.perceive(out["lidar"][i], headings[i], with_points=False) for i in evaluated}
            clean.update({i: pipe.resample_gathered(gathered[i]) for i in evaluated})
            stages["accuracy"] = (accuracy, evaluated)
            calls["_evaluated"] = repeat * len(evaluated)
        elif name == "step":
            stages["step"] = (step, everything)
        fn, which = stages[name]
        if which:
            fn(which[0])                                    # warm-up, outside the meter
        with meter.collect(name):
            for _ in range(repeat):
                res = {i: fn(i) for i in which}
        out[name] = res
        calls[name] = repeat * len(which)
        if name == upto:
            break
    part.close()
    return calls


# -- callgrind dumps ---------------------------------------------------------------------------------------------
def dump_totals(paths: list[Path]) -> dict[str, int]:
    """Instructions (Ir) per dump name, summed over the callgrind output files ``paths``."""
    out: dict[str, int] = {}
    for p in paths:
        text = p.read_text(errors="replace")
        name = re.search(r"^desc: Trigger: Client Request: (.*)$", text, re.M)
        total = re.search(r"^(?:summary|totals): (\d+)", text, re.M)
        if name and total:
            out[name.group(1).strip()] = out.get(name.group(1).strip(), 0) + int(total.group(1))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("record", help="record a scenario's perception inputs")
    r.add_argument("--out", type=Path, required=True)
    r.add_argument("--scenario", default="default")
    r.add_argument("--renderer", choices=("gl", "mock"), default=None)
    r.add_argument("--frames", type=int, default=None, help="frames to simulate (default: the whole scenario)")
    r.add_argument("--every", type=int, default=20)
    r.add_argument("--offsets", default="0,7", help="kept frames: frame %% every in these")
    r.add_argument("--start", type=int, default=0, help="keep no frame before this one")
    p = sub.add_parser("replay", help="replay a recording")
    p.add_argument("recording", type=Path)
    p.add_argument("--limit", type=int, default=None, help="first LIMIT recorded frames only")
    p.add_argument("--save", type=Path, help="write the outputs (reference for --check)")
    p.add_argument("--check", type=Path, help="compare the outputs bit for bit with a saved reference")
    p.add_argument("--stages", action="store_true", help="measure the stages one by one")
    p.add_argument("--repeat", type=int, default=1)
    p.add_argument("--callgrind", action="store_true", help="collect stages under callgrind instead of timing")
    p.add_argument("--focus", action="append", default=[], metavar="STAGE:MODULE:FUNCTION",
                   help="with --callgrind, also collect inside one function during one stage (repeatable)")
    t = sub.add_parser("totals", help="instructions per stage from callgrind output files")
    t.add_argument("files", type=Path, nargs="+")
    t.add_argument("--calls", type=Path, help="the calls JSON a --callgrind replay printed (per-call figures)")
    a = ap.parse_args()
    if a.cmd == "record":
        extra = {"renderer": a.renderer} if a.renderer else {}
        if a.renderer == "mock":
            extra["render"] = {"mock_scale": 1.0}
        sc = load_scenario(resolve_scenario_arg(a.scenario), extra=extra or None)
        n = record(sc, a.out, a.every, tuple(int(x) for x in a.offsets.split(",")), a.frames, a.start)
        print(f"kept {n} frames in {a.out}")
    elif a.cmd == "replay":
        rec = Recording(a.recording, a.limit)
        if a.save or a.check:
            out = replay_outputs(rec)
            if a.save:
                np.savez_compressed(a.save, **out)
                print(f"saved outputs of {len(rec.frames)} frames to {a.save}")
            if a.check:
                ref = dict(np.load(a.check))
                if a.limit is not None:
                    ref = {k: (v if k == "state_names" else v[:a.limit]) for k, v in ref.items()}
                problems = compare(out, ref)
                print("bit-identical" if not problems else "DIFFERENT:\n  " + "\n  ".join(problems))
                if problems:
                    sys.exit(1)
        if a.stages:
            meter = _Callgrind() if a.callgrind else _Clock()
            calls = run_stages(rec, meter, a.repeat)
            for spec in a.focus if a.callgrind else ():
                run_stages(rec, _Focus(meter, spec), a.repeat, upto=spec.partition(":")[0])
            print(json.dumps(calls))
            if isinstance(meter, _Clock):
                print("| stage | calls | wall ms per call | CPU ms per call |")
                print("|---|---:|---:|---:|")
                for s in STAGES:
                    w, c = meter.rows[s]
                    n = max(calls[s], 1)
                    print(f"| {s} | {calls[s]} | {1e3 * w / n:.3f} | {1e3 * c / n:.3f} |")
    else:
        totals = dump_totals(a.files)
        calls = json.loads(a.calls.read_text()) if a.calls else {}
        print("| stage | instructions (M) | calls | M per call |")
        print("|---|---:|---:|---:|")
        for s in sorted(totals, key=lambda k: (STAGES.index(k.split("/")[0]) if k.split("/")[0] in STAGES
                                               else len(STAGES), k)):
            n = calls.get(s.split("/")[0], 0)
            per = f"{totals[s] / n / 1e6:.2f}" if n else ""
            print(f"| {s} | {totals[s] / 1e6:.1f} | {n or ''} | {per} |")


if __name__ == "__main__":
    main()
