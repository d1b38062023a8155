"""Where a perception frame's CPU goes: each ring member's step, and the GL renderer's parts.

The default scenario in one process (``cosim.runtime.inprocess``: the participants and blocks of a launched run;
``frames`` frames after ``warmup``) with llvmpipe in the calling thread (``LP_NUM_THREADS=0``, set before GL loads:
the case runs in a fresh worker process), so that thread CPU time (``time.thread_time``) holds all of a step's
work. Per frame, medians over frames:

* ``dynamics``, ``renderer``, ``perception`` (the step and, for an overlapping member, the rest of its step:
  ``<member>.rest``), ``supervisor`` (``Recorder.record``);
* the renderer's parts: ``scene`` (``scene_from_state``), ``upload`` (``set_scene``), ``draw`` (uniforms, state, and
  llvmpipe's vertex and geometry shading, which run in the calling thread at the draw call), ``raster``
  (``read_depth``: llvmpipe rasterises and shades the fragments when the image is read), ``rest``;
* with ``split_draws`` each draw call is followed by ``ctx.finish()``, so its raster work is timed apart
  (``<draw>.call`` / ``<draw>.raster``); the finishes change llvmpipe's batching a little, so the totals of that mode
  are not the headline;
* ``faults``: minor page faults per frame of the whole process (``getrusage``), which CPU time does not separate.

``fragments`` counts instead, with GL pipeline-statistics queries around each draw call (llvmpipe's own counters,
``ARB_pipeline_statistics_query``): fragment shader invocations (``<draw>.shaded``; llvmpipe shades whole 4 x 4
stamps, so these are multiples of 16), the fragments that passed the shader and the depth test (``<draw>.passed``,
a samples-passed query) and the geometry shader's emitted primitives (``<draw>.emitted``: two per rectangle), per
frame, medians, and the target's ``beams``. Counts do not depend on the machine's load.
"""
from __future__ import annotations

import os
import resource
import statistics
import time

from harness import Context, case

__all__ = ["frame_parts", "frame_path"]

#: the renderer's parts (the rest of its step is ``renderer: rest``)
PARTS = ("renderer: scene", "renderer: upload", "renderer: draw", "renderer: raster")


def _timed(obj, name: str, into: list, clock=time.thread_time) -> None:
    """Wrap ``obj.name`` so that each call's thread CPU time (s) is appended to ``into``."""
    fn = getattr(obj, name)

    def wrapped(*args, **kwargs):
        c = clock()
        out = fn(*args, **kwargs)
        into.append(clock() - c)
        return out

    setattr(obj, name, wrapped)


def _split_draws(be, series) -> None:
    """Time each of the beam renderer's draw calls apart from its raster work (a finish after each)."""
    import renderer_proc.gl.beam as bg

    ctx, render = be.ctx, be._render

    def one(name):
        c = time.thread_time()
        render(name)
        c1 = time.thread_time()
        ctx.finish()
        series(f"{name}.call").append(c1 - c)
        series(f"{name}.raster").append(time.thread_time() - c1)
    be._render = one
    surf, surf_render = be._surface, be._surface.render

    def surface():
        c = time.thread_time()
        surf_render()
        c1 = time.thread_time()
        ctx.finish()
        series("surface.call").append(c1 - c)
        series("surface.raster").append(time.thread_time() - c1)
    surf.render = surface
    begin = bg.begin_frame

    def begin_frame(*args):
        ctx.finish()
        c = time.thread_time()
        begin(*args)
        ctx.finish()
        series("begin_frame").append(time.thread_time() - c)
    bg.begin_frame = begin_frame


#: GL query targets: ARB_pipeline_statistics_query's fragment shader invocations and geometry shader primitives
#: emitted, and the core samples-passed query
_QUERIES = {"shaded": 0x82F4, "emitted": 0x82F3, "passed": 0x8914}
_QUERY_RESULT = 0x8866


def _gl(name: str, *args):
    """A GL entry point of the current EGL context (ctypes)."""
    import ctypes

    egl = ctypes.CDLL("libEGL.so.1")
    egl.eglGetProcAddress.restype, egl.eglGetProcAddress.argtypes = ctypes.c_void_p, [ctypes.c_char_p]
    return ctypes.CFUNCTYPE(None, *args)(egl.eglGetProcAddress(name.encode()))


def _count_draws(be, series) -> None:
    """Count each of the beam renderer's draw calls (module docstring: ``fragments``)."""
    import ctypes

    u, u64 = ctypes.c_uint, ctypes.c_uint64
    gen, begin = _gl("glGenQueries", ctypes.c_int, ctypes.POINTER(u)), _gl("glBeginQuery", u, u)
    end, get = _gl("glEndQuery", u), _gl("glGetQueryObjectui64v", u, u, ctypes.POINTER(u64))
    ids = (u * len(_QUERIES))()
    gen(len(_QUERIES), ids)

    def counted(name, fn):
        def call(*args):
            for q, target in zip(ids, _QUERIES.values()):
                begin(target, q)
            fn(*args)
            for target in _QUERIES.values():
                end(target)
            for q, key in zip(ids, _QUERIES):
                v = u64()
                get(q, _QUERY_RESULT, ctypes.byref(v))
                series(f"{name}.{key}").append(float(v.value))
        return call
    render = be._render
    be._render = lambda name: counted(name, render)(name)
    be._surface.render = counted("surface", be._surface.render)


def frame_parts(scenario, frames: int, warmup: int, split_draws: bool = False,
                fragments: bool = False) -> dict[str, float]:
    """Median thread-CPU ms per frame of every part (module docstring) and ``faults`` per frame; with ``fragments``
    the draw calls' counts instead."""
    import renderer_proc.participant as rp
    from cosim.runtime.heap import keep_heap
    from cosim.runtime.inprocess import InProcessSession

    keep_heap()
    sess = InProcessSession(scenario)
    t: dict[str, list] = {}

    def series(key: str) -> list:
        return t.setdefault(key, [])

    scene_fn = rp.scene_from_state
    try:
        for name, p in sess.participants.items():
            step, rest_t, step_t = p.step, series(f"{name}.rest"), series(name)

            def member(frame, step=step, rest_t=rest_t, step_t=step_t):
                c = time.thread_time()
                rest = step(frame)
                step_t.append(time.thread_time() - c)
                if rest is None:
                    return None

                def timed_rest(rest=rest):
                    c2 = time.thread_time()
                    rest()
                    rest_t.append(time.thread_time() - c2)
                return timed_rest
            p.step = member
        _timed(sess.recorder, "record", series("supervisor"))
        be = sess.participants["renderer"].backend
        _timed(be, "set_scene", series("renderer: upload"))
        _timed(be, "draw", series("renderer: draw"))
        _timed(be, "read_depth", series("renderer: raster"))
        scene_t = series("renderer: scene")

        def scene(*args):
            c = time.thread_time()
            out = scene_fn(*args)
            scene_t.append(time.thread_time() - c)
            return out
        rp.scene_from_state = scene
        if split_draws:
            _split_draws(be, series)
        if fragments:
            _count_draws(be, series)
        for _ in range(warmup):
            sess.step()
        for v in t.values():
            v.clear()
        r0 = resource.getrusage(resource.RUSAGE_SELF)
        n = 0
        while not sess.done and n < frames:
            sess.step()
            n += 1
        r1 = resource.getrusage(resource.RUSAGE_SELF)
    finally:
        rp.scene_from_state = scene_fn
        sess.close()
    if fragments:
        return {**{k: statistics.median(v) for k, v in t.items() if k.rpartition(".")[2] in _QUERIES and v},
                "beams": float(be.layout.shape[0] * be.layout.shape[1])}
    out = {k: 1e3 * statistics.median(v) for k, v in t.items() if v}
    out["renderer: rest"] = out["renderer"] - sum(out.get(k, 0.0) for k in PARTS)
    out["faults"] = (r1.ru_minflt - r0.ru_minflt) / max(n, 1)
    return out


@case("frame_path", "where a perception frame's CPU goes: each member's step, the GL renderer's parts, page faults",
      options={"scenario": "default", "frames": 400, "warmup": 100, "split_draws": False, "fragments": False},
      quick={"frames": 5, "warmup": 2}, settings=True)
def frame_path(ctx: Context) -> dict:
    """Thread CPU ms per frame of every part of a frame (module docstring)."""
    os.environ.setdefault("LP_NUM_THREADS", "0")                  # before GL loads: llvmpipe in the calling thread
    res = frame_parts(ctx.scenario(ctx["scenario"]), ctx["frames"], ctx["warmup"], ctx["split_draws"],
                      ctx["fragments"])
    if ctx["fragments"]:
        return {"llvmpipe's counters per frame (medians)": {k: {"count": v} for k, v in res.items()}}
    faults = res.pop("faults")
    return {f"thread CPU per frame (LP_NUM_THREADS={os.environ['LP_NUM_THREADS']})":
            {k: {"ms per frame": v} for k, v in res.items()}, "minor page faults": {"per frame": {"faults": faults}}}
