"""Stand-in ring members for runtime tests: tiny, deterministic, with fault injection.

Each role writes a struct, a trace array (frame, monotonic ns) and, for the renderer, an image. Faults are
chosen per role with keyword arguments: ``crash_at`` (raise), ``kill_at`` (SIGKILL itself), ``exit_at``
(os._exit without report), ``hang_at`` (block far longer than any timeout, still beating), ``stop_at`` (SIGSTOP
itself; ``stop_at=-2``: in ``start``, before frame 0), ``deadlock_at`` (sleep in C holding the GIL, so its
heartbeat thread stops too), ``busy_at`` (``busy_s`` of CPU in one C call that keeps the GIL: slow, not hung), ``spin_at`` (a Python loop
that never ends: it beats and uses CPU time, a runaway); in ``start``: ``start_busy_s`` (that much CPU time, like
compiling shaders: slow, not hung) and ``start_block`` (wait forever on an event: a start-up that makes no
progress); both say their activity (cosim.runtime.participant.activity);
``stamp_file`` receives the monotonic time of a ``kill_at``/``stop_at``/``deadlock_at`` fault.

:func:`real_specs` puts the same faults into the real participants (dynamics, renderer, perception): a run that
records what a real run records, and so draws figures when it completes.
"""
from __future__ import annotations

import ctypes
import os
import signal
import threading
import time
from dataclasses import replace

import numpy as np

from cosim.runtime.participant import activity
from cosim.runtime.specs import ParticipantSpec
from shm_schema import ArrayBlock, Field, StructBlock, image_block

IMG_H, IMG_W = 48, 64


def blocks_dynamics(scenario):
    return [StructBlock("fake_dyn", "dynamics", (Field("t_s", "s"), Field("x_m", "m"),
                                                 Field("perc_frame", "", "i8"))),
            ArrayBlock("trace_dynamics", "dynamics", "i8", (scenario.frames + 1, 2)),
            ArrayBlock("heightmap_truth", "dynamics", "f4", (6, 3))]


def blocks_renderer(scenario):
    return [StructBlock("fake_ren", "renderer", (Field("dyn_frame", "", "i8"), Field("x_seen_m", "m"))),
            ArrayBlock("trace_renderer", "renderer", "i8", (scenario.frames + 1, 2)),
            image_block("cam0_depth", "renderer", IMG_H, IMG_W)]


def blocks_perception(scenario):
    return [StructBlock("fake_perc", "perception", (Field("img_frame", "", "i8"), Field("checksum", ""))),
            ArrayBlock("trace_perception", "perception", "i8", (scenario.frames + 1, 2))]


class Fake:
    """One stand-in role; the fault keywords pick the frame at which it misbehaves (-1: never)."""

    def __init__(self, scenario, role, crash_at=-1, kill_at=-1, exit_at=-1, hang_at=-1, start_busy_s=0.0, start_block=False,
                 stamp_file="", defer=False, rest_s=0.0, stop_at=-1, deadlock_at=-1, busy_at=-1, busy_s=0.0, spin_at=-1):
        self.name = role
        #: perception only: publish one turn late and return the rest of the step (cosim.runtime.participant);
        #: ``rest_s``: how long that rest takes (a sleep: lets a test see it overlap the next frame)
        self.defer, self.rest_s, self.pending = defer, rest_s, None
        self.scenario = scenario
        self.faults = dict(crash_at=crash_at, kill_at=kill_at, exit_at=exit_at, hang_at=hang_at, stop_at=stop_at,
                           deadlock_at=deadlock_at, busy_at=busy_at, spin_at=spin_at)
        self.busy_s = busy_s
        self.start_busy_s, self.start_block = start_busy_s, start_block
        self.stamp_file = stamp_file
        self.seg = None

    def start(self, segment):
        self.seg = segment
        if self.faults["stop_at"] == -2:
            self._stamp()
            os.kill(os.getpid(), signal.SIGSTOP)
        if self.start_busy_s:
            activity("compiling shaders (a stand-in)")
            _busy_holding_the_gil(self.start_busy_s)
        if self.start_block:
            activity("waiting for a licence server")
            self._stamp()
            threading.Event().wait(3600.0)

    def _stamp(self):
        if self.stamp_file:  # CLOCK_MONOTONIC is system-wide: the test compares it with its own clock
            with open(self.stamp_file, "w") as f:
                f.write(repr(time.monotonic()))

    def _faults(self, frame):
        if frame in (self.faults["crash_at"], self.faults["hang_at"], self.faults["spin_at"]):
            self._stamp()
        if frame == self.faults["crash_at"]:
            raise ValueError(f"injected crash in {self.name} at frame {frame}")
        if frame == self.faults["kill_at"]:
            if self.stamp_file:  # CLOCK_MONOTONIC is system-wide: the test compares it with its own clock
                with open(self.stamp_file, "w") as f:
                    f.write(repr(time.monotonic()))
            os.kill(os.getpid(), signal.SIGKILL)
        if frame == self.faults["exit_at"]:
            os._exit(3)
        if frame == self.faults["hang_at"]:
            threading.Event().wait(3600.0)
        if frame == self.faults["stop_at"]:
            self._stamp()
            os.kill(os.getpid(), signal.SIGSTOP)
        if frame == self.faults["busy_at"]:
            _busy_holding_the_gil(self.busy_s)
        if frame == self.faults["spin_at"]:
            while True:
                pass
        if frame == self.faults["deadlock_at"]:
            self._stamp()
            ctypes.PyDLL(None).sleep(3600)  # a PyDLL call keeps the GIL: no Python thread runs meanwhile

    def step(self, frame):
        self._faults(frame)
        seg = self.seg
        started = time.monotonic_ns()
        # every input is read before the first write (the pipelined schedule hands the inputs back at that write)
        if self.name == "dynamics":
            perc_frame = seg.frame_of("fake_perc") if seg.has("fake_perc") else -1
        elif self.name == "renderer":
            x, dyn_frame = seg.view("fake_dyn").x_m, seg.frame_of("fake_dyn")
        else:
            self.flush()
            img, img_frame = seg.view("cam0_depth")[..., 0].copy(), seg.frame_of("cam0_depth")
        with seg.write(f"trace_{self.name}", frame) as tr:
            tr[frame] = (frame, started)
        dt = self.scenario.timing.sensor_period_s
        if self.name == "dynamics":
            with seg.write("fake_dyn", frame) as v:
                v.t_s = frame * dt
                v.x_m = 2.0 * frame * dt + 0.1 * np.sin(frame)
                v.perc_frame = perc_frame
            with seg.write("heightmap_truth", frame) as h:
                h[...] = frame * 0.01
        elif self.name == "renderer":
            with seg.write("cam0_depth", frame) as img:
                img[...] = frame % 251
            with seg.write("fake_ren", frame) as v:
                v.dyn_frame = dyn_frame
                v.x_seen_m = x
        elif not self.defer:
            with seg.write("fake_perc", frame) as v:
                v.img_frame = img_frame
                v.checksum = float(img.astype(np.int64).sum())
        else:
            def rest():
                if self.rest_s:
                    time.sleep(self.rest_s)
                self.pending = (frame, img_frame, float(img.astype(np.int64).sum()))
            return rest
        return None

    def flush(self):
        if self.pending is not None:
            frame, img_frame, checksum = self.pending
            with self.seg.write("fake_perc", frame) as v:
                v.img_frame, v.checksum = img_frame, checksum
            self.pending = None

    def close(self):
        self.seg = None


def _busy_holding_the_gil(seconds: float) -> None:
    """Burn CPU for about ``seconds`` in one C call that keeps the GIL (regex backtracking, ~1.85x per extra
    character, sized from a short timed call), like one long draw call."""
    import math
    import re

    pattern, n0 = re.compile(r"(a+)+$"), 20
    t0 = time.perf_counter()
    pattern.match("a" * n0 + "b")
    small = max(time.perf_counter() - t0, 1e-4)
    n = n0 + max(0, round(math.log(seconds / small) / math.log(1.85)))
    pattern.match("a" * n + "b")


def make(scenario, role="dynamics", **faults):
    return Fake(scenario, role, **faults)


def always(scenario):
    return True


def specs(**faults_by_role):
    """Stand-in specs for the three roles; ``faults_by_role={'renderer': {'crash_at': 3}}``; a perception with
    ``defer=True`` is planned as a deferred member."""
    out = {}
    for role in ("dynamics", "renderer", "perception"):
        kw = faults_by_role.get(role, {})
        out[role] = ParticipantSpec(role, "cosim.testing.fakes:make", f"cosim.testing.fakes:blocks_{role}", kwargs={"role": role, **kw},
                                    defers="cosim.testing.fakes:always" if kw.get("defer") else None)
    return out


def reads_dynamics(scenario):
    return {}


def reads_renderer(scenario):
    return {"dynamics": 0}


def reads_perception(scenario):
    return {"renderer": 0}


def pipelined_specs(**faults_by_role):
    """:func:`specs` with each role's reads declared, so that a launched run can use the pipelined schedule
    (cosim.runtime.pipeline): the renderer reads dynamics' frame, perception the renderer's."""
    return {role: replace(spec, reads=f"cosim.testing.fakes:reads_{role}") for role, spec in specs(**faults_by_role).items()}


def observe(segment, stop_self=False):
    """A stand-in observer (cosim.runtime.launcher.ObserverSpec target): idles until it is ended; with
    ``stop_self`` it SIGSTOPs itself first (a hung viewer)."""
    if stop_self:
        os.kill(os.getpid(), signal.SIGSTOP)
    threading.Event().wait(3600.0)


class RealWithFaults:
    """A real participant (``DEFAULT_SPECS[role]``) with :class:`Fake`'s fault keywords injected before its step."""

    def __init__(self, scenario, role, **faults):
        from cosim.runtime.specs import DEFAULT_SPECS

        self.name = role
        self._inner = DEFAULT_SPECS[role].create(scenario)
        self._faulty = Fake(scenario, role, **faults)

    def start(self, segment):
        self._faulty.start(segment)
        self._inner.start(segment)

    def step(self, frame):
        self._faulty._faults(frame)
        return self._inner.step(frame)

    def __getattr__(self, name):  # flush, close, settable, ...
        return getattr(self._inner, name)


def make_real(scenario, role="dynamics", **faults):
    return RealWithFaults(scenario, role, **faults)


def real_specs(scenario, **faults_by_role):
    """The scenario's real ring members, with faults as in :func:`specs` (``{'renderer': {'crash_at': 3}}``)."""
    from dataclasses import replace

    from cosim.runtime.specs import ring_specs

    return {s.name: replace(s, factory=f"{__name__}:make_real", kwargs={"role": s.name, **faults_by_role.get(s.name, {})})
            for s in ring_specs(scenario)}
