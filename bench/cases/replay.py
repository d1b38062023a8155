"""Perception replayed on recorded inputs (``cases/_replay.py``): per-stage cost, wall and CPU or callgrind
instructions, and a bit-identity check of the outputs.

The recording (``recording``; by default made once into ``bench/out/replay/`` from the ``record_*`` options with the
mock renderer at ``render.mock_scale`` 1.0, which writes the GL renderer's bytes) is replayed by every arm, so an
A/B of source trees compares their perception code on the same inputs. The stages one by one over all recorded
frames (``repeat`` passes), each after one unmetered warm-up call: lidar (resample + noise), points (the
lidar_points record), level (level points and border flags), cart, heightmap, impact, accuracy (the evaluated
frames), and the whole participant step (copying the inputs into the segment left out). The stages before ``step``
take the level frame of flat ground (no atmosphere); ``step`` is the participant as it runs. The thread pools are
single-threaded, as in a run's processes (``cosim.runtime.threadpools``).

``meter=callgrind`` runs the stages under ``valgrind --tool=callgrind`` and counts each stage's instructions
(``harness.callgrind``); ``focus`` (``STAGE:MODULE:FUNCTION`` or ``STAGE:MODULE:Class.method``, ``;``-separated) adds
the inclusive count of one function within a stage. ``save`` writes the replay's outputs; ``check`` compares them
bit for bit with saved ones. The stages look their functions up in their modules (``perception_proc.estimates.rim``,
``.heightmap``, ``.impact``) at each call, so a focus names e.g. ``cart:perception_proc.estimates.rim:find_cart``.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

from harness import Context, case

__all__ = ["Clock", "Focus", "perception_replay", "recording_path", "run_stages", "stages_under_callgrind"]

#: stages timed or counted one by one, in pipeline order
STAGES = ("lidar", "points", "level", "cart", "heightmap", "impact", "accuracy", "step")
#: where recordings made on demand are kept
REPLAY_DIR = Path(__file__).resolve().parents[1] / "out" / "replay"


class Clock:
    """Wall time (``time.perf_counter``) and process CPU time per stage."""

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
            self.rows[name] = (time.perf_counter() - w - self._excluded[0], time.process_time() - c - self._excluded[1])

    @contextmanager
    def exclude(self) -> Iterator[None]:
        w, c = time.perf_counter(), time.process_time()
        try:
            yield
        finally:
            self._excluded[0] += time.perf_counter() - w
            self._excluded[1] += time.process_time() - c


class Focus:
    """Callgrind collection only inside ``module:function`` while stage ``stage`` runs (inclusive instructions of that
    function, dumped as ``stage/module:function``); other stages are not collected."""

    def __init__(self, requests, spec: str):
        self.lib = requests.lib
        self.stage, _, self.target = spec.partition(":")
        self.module, _, self.function = self.target.partition(":")

    @contextmanager
    def exclude(self) -> Iterator[None]:
        yield

    @contextmanager
    def collect(self, name: str) -> Iterator[None]:
        if name != self.stage:
            yield
            return
        import functools
        import importlib

        owner = importlib.import_module(self.module)
        *owners, attr = self.function.split(".")
        for o in owners:
            owner = getattr(owner, o)
        fn, depth, lib = getattr(owner, attr), [0], self.lib

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

        setattr(owner, attr, wrapped)
        lib.cg_zero()
        try:
            yield
        finally:
            setattr(owner, attr, fn)
            lib.cg_dump(f"{self.stage}/{self.target}".encode())


def run_stages(rec, meter, repeat: int = 1, upto: str | None = None) -> dict[str, int]:
    """Each stage over every recorded frame (``repeat`` times), in frame order, after one call outside the meter;
    the inputs of later stages are computed outside the meter as well. Stages after ``upto`` are left out. Returns
    the number of metered calls per stage."""
    from cases._replay import load_inputs, local_segment
    from perception_proc.accuracy import stage as acc
    from perception_proc.estimates import (
        heightmap as heightmap_module,  # functions looked up per call: a focus wraps them
    )
    from perception_proc.estimates import impact as impact_module
    from perception_proc.estimates import rim as rim_module
    from perception_proc.participant import PerceptionParticipant

    seg = local_segment(rec.scenario)
    part = PerceptionParticipant(rec.scenario)
    part.start(seg)
    pipe, sc = part.pipeline, rec.scenario
    sigma = sc.sensor.noise.range_sigma_m
    frames = [int(f) for f in rec.frames]
    gathered = [pipe.gather([rec.images[name][i] for name, _ in part._images]) for i in range(len(frames))]
    headings = [part._heading(st, acc.world_from_parent(sc, st)) for st in rec.states]
    out: dict[str, dict] = {}
    clean = {}

    def lidar(i):
        return pipe.noisy(pipe.resample_gathered(gathered[i]), frames[i])

    def level(i):
        r = out["lidar"][i]
        return pipe.level_points(r), rim_module.border_beams(r, pipe.shape)

    def cart(i):
        p, b = out["level"][i]
        return rim_module.find_cart(p, b, sc.cart, headings[i], sigma)

    def heightmap(i):
        return heightmap_module.height_map(out["level"][i][0], out["cart"][i].level_from_grid, sc.cart,
                                           sc.controller.grid_cell_m, sc.perception.min_points_per_cell, sigma)

    def impact(i):
        lfg, hm = out["cart"][i].level_from_grid, out["heightmap"][i]
        sg = (pipe.level_from_sensor[:3, 3] - lfg[:3, 3]) @ lfg[:3, :3]
        heights = hm.heights.copy()
        imp = impact_module.find_impact(hm.grid_points, hm.stream, heights, pipe.cell_xy,
                                        sc.perception.impact_search_radius_m, (float(sg[0]), float(sg[1])))
        impact_module.blank_under_stream(heights, imp, pipe.cell_xy)
        return imp

    def accuracy(i):
        st, beams = rec.states[i], part._accuracy_beams(frames[i])
        return part._accuracy(st, beams, clean[i][beams], out["perceived"][i], acc.world_from_parent(sc, st),
                              pipe.level_from_sensor, rec.truth["heightmap_truth"][i], rec.truth["stream"][i])

    def step(i):
        with meter.exclude():
            load_inputs(seg, rec, i)
        rest = part.step(frames[i])
        if rest is not None:
            rest()
        part.flush()

    everything = list(range(len(frames)))
    stages = {"lidar": (lidar, everything), "points": (lambda i: pipe.points(out["lidar"][i]), everything),
              "level": (level, everything), "cart": (cart, everything), "step": (step, everything)}

    def cart_stages():
        with_cart = [i for i in everything if out["cart"][i].valid]
        stages["heightmap"] = (heightmap, with_cart)
        stages["impact"] = (impact, with_cart)

    def accuracy_stage():
        evaluated = [i for i in everything if part._accuracy_beams(frames[i]) is not None]
        out["perceived"] = {i: pipe.perceive(out["lidar"][i], headings[i], with_points=False) for i in evaluated}
        clean.update({i: pipe.resample_gathered(gathered[i]) for i in evaluated})
        stages["accuracy"] = (accuracy, evaluated)

    calls = _meter_stages(meter, stages, {"heightmap": cart_stages, "accuracy": accuracy_stage}, out, repeat, upto)
    part.close()
    return calls


def _meter_stages(meter, stages: dict, late: dict, out: dict, repeat: int, upto: str | None) -> dict[str, int]:
    """Meter the :data:`STAGES` in order (``stages``: name -> (function of a frame index, the indices)), each once
    outside the meter first; ``late``: name -> what adds that stage (and its inputs) once the stages before it have
    run. Stages after ``upto`` are left out; each stage's results go to ``out[name]``. The metered calls per stage."""
    calls: dict[str, int] = {}
    for name in STAGES:
        if name in late:
            late[name]()
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
    return calls


def recording_path(ctx: Context) -> Path:
    """The recording to replay: ``recording``, or one made now from the ``record_*`` options (kept in
    :data:`REPLAY_DIR` for the next sample and the other arms)."""
    if ctx["recording"]:
        return ctx.path(ctx["recording"])
    frames, every, offsets, start = ctx["record_frames"], ctx["record_every"], str(ctx["record_offsets"]), \
        ctx["record_start"]
    path = REPLAY_DIR / (f"{ctx['scenario']}-{ctx['record_renderer']}-f{frames or 'all'}-e{every}-"
                         f"o{offsets.replace(',', '_')}-s{start}.npz")
    if not path.exists():
        from cases._replay import record

        extra = {"renderer": ctx["record_renderer"]}
        if ctx["record_renderer"] == "mock":
            extra["render"] = {"mock_scale": 1.0}
        n = record(ctx.scenario(ctx["scenario"], extra=extra), path, every,
                   tuple(int(x) for x in offsets.split(",")), frames, start)
        print(f"recorded {n} frames into {path}", file=sys.stderr)
    return path


def _callgrind_stages(ctx: Context, path: Path) -> tuple[dict[str, int], dict[str, int]]:
    """(instructions per stage or focus, calls per stage) from a replay under callgrind in the arm's tree."""
    from harness.callgrind import dump_totals

    bench = Path(__file__).resolve().parents[1]
    code = ("import sys, json; sys.path.insert(0, {bench!r}); from cosim.runtime.threadpools import "
            "default_to_single_threaded_pools; default_to_single_threaded_pools(); from cases import replay; "
            "print(json.dumps(replay.stages_under_callgrind({path!r}, {limit!r}, {repeat!r}, {focus!r})))").format(
        bench=str(bench), path=str(path), limit=ctx["limit"], repeat=ctx["repeat"], focus=ctx["focus"])
    env = dict(os.environ, PYTHONPATH=str(ctx.tree), PYTHONHASHSEED="0")
    with tempfile.TemporaryDirectory(prefix="bench-cg-") as tmp:
        proc = subprocess.run(["valgrind", "--tool=callgrind", "--collect-atstart=no",
                               f"--callgrind-out-file={tmp}/cg.%p", sys.executable, "-c", code], cwd=ctx.tree, env=env,
                              check=True, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        totals = dump_totals(sorted(Path(tmp).glob("cg.*")))
    return totals, json.loads(proc.stdout.strip().splitlines()[-1])


def stages_under_callgrind(path: str, limit, repeat: int, focus: str) -> dict[str, int]:
    """Inside valgrind: every stage collected and dumped under its name, then each focus; returns the calls."""
    from harness.callgrind import ClientRequests

    from cases._replay import Recording

    rec, meter = Recording(Path(path), limit), ClientRequests()
    calls = run_stages(rec, meter, repeat)
    for spec in (s for s in focus.split(";") if s):
        run_stages(rec, Focus(meter, spec), repeat, upto=spec.partition(":")[0])
    return calls


@case("perception_replay", "perception replayed on recorded inputs: CPU per call of each stage (or callgrind "
      "instructions), outputs bit for bit",
      options={"recording": "", "scenario": "default", "record_frames": None, "record_every": 20,
               "record_offsets": "0,7", "record_start": 0, "record_renderer": "mock", "limit": None, "repeat": 1,
               "meter": "clock", "focus": "", "save": "", "check": ""},
      quick={"record_frames": 30}, rounds=3, compare=("CPU ms per call", "instructions M per call"))
def perception_replay(ctx: Context) -> dict:
    """The stages over the recording (module docstring); ``limit``: the first frames only."""
    from cases._replay import Recording, compare, replay_outputs
    from cosim.runtime.threadpools import default_to_single_threaded_pools

    default_to_single_threaded_pools()
    path = recording_path(ctx)
    rec = Recording(path, ctx["limit"])
    out: dict = {}
    if ctx["save"] or ctx["check"]:
        import numpy as np

        res = replay_outputs(rec)
        if ctx["save"]:
            np.savez_compressed(ctx.path(ctx["save"]), **res)
        if ctx["check"]:
            ref = dict(np.load(ctx.path(ctx["check"])))
            if ctx["limit"] is not None:
                ref = {k: (v if k == "state_names" else v[:ctx["limit"]]) for k, v in ref.items()}
            problems = compare(res, ref)
            out["outputs against the reference"] = {Path(ctx["check"]).name: {
                "differences": len(problems), "what": "; ".join(problems) or "bit-identical"}}
    if ctx["meter"] == "callgrind":
        totals, calls = _callgrind_stages(ctx, path)
        rows = {}
        for key in sorted(totals, key=lambda k: (STAGES.index(k.split("/")[0]) if k.split("/")[0] in STAGES
                                                 else len(STAGES), k)):
            n = calls.get(key.split("/")[0], 0)
            rows[key] = {"calls": n, "instructions M": totals[key] / 1e6,
                         "instructions M per call": totals[key] / n / 1e6 if n else None}
        out[f"{path.name}: callgrind instructions per stage"] = rows
    else:
        meter = Clock()
        calls = run_stages(rec, meter, ctx["repeat"])
        out[f"{path.name}: {len(rec.frames)} frames"] = {
            s: {"calls": calls[s], "wall ms per call": 1e3 * meter.rows[s][0] / max(calls[s], 1),
                "CPU ms per call": 1e3 * meter.rows[s][1] / max(calls[s], 1)} for s in STAGES}
    return out
