"""Live viewer of a running co-simulation, and the dashboard it serves.

``python -m cosim.viewer --attach RUN`` (a run directory or a segment name) attaches read-only, learns the
layout from the segment, reads seqlock-consistent snapshots, and serves a local web dashboard on 127.0.0.1.
``launch.py run ... --viewer`` starts the same thing as an observer process of the run. It never takes part
in the lockstep, may drop frames, and never deletes the segment. ``--replay FILE.mcap`` serves a recording
(:mod:`cosim.recording`) to the same dashboard.

Modules: :mod:`.live` (attach, snapshots, end of run), :mod:`.snapshot` (what a snapshot holds, field
discovery), :mod:`.panels` (panel availability and PNG drawings), :mod:`.page` (the HTML page),
:mod:`.server` (HTTP server, observer entry), :mod:`.__main__` (command line), :mod:`.viewinfo` (what the
dashboard knows of the scenario), :mod:`.clouds` (the point clouds in the cart frame), :mod:`.fill` (the
fullness bars' rule), :mod:`.draw` (drawing primitives).
"""
import importlib

__all__ = ["LiveSource", "RunEnded", "RunNotFound", "resolve_run", "DashboardServer", "observe", "serve",
           "DEFAULT_PORT"]

#: where each public name lives: imported on first use, so that a module needing only a light part (the recorder
#: takes :mod:`.viewinfo`) does not import the server and OpenCV
_HOMES = {"LiveSource": "live", "RunEnded": "live", "RunNotFound": "live", "resolve_run": "live",
          "DashboardServer": "server", "observe": "server", "serve": "server", "DEFAULT_PORT": "server"}


def __getattr__(name: str):
    if name in _HOMES:
        return getattr(importlib.import_module(f".{_HOMES[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
