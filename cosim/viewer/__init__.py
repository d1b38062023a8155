"""Live viewer of a running co-simulation, and the dashboard it serves.

``python -m cosim.viewer --attach RUN`` (a run directory or a segment name) attaches read-only, learns the
layout from the segment, reads seqlock-consistent snapshots, and serves a local web dashboard on 127.0.0.1.
``launch.py run ... --viewer`` starts the same thing as an observer process of the run. It never takes part
in the lockstep, may drop frames, and never deletes the segment. ``--replay FILE.mcap`` serves a recording
(:mod:`cosim.recording`) to the same dashboard.

Modules: :mod:`.live` (attach, snapshots, end of run), :mod:`.snapshot` (what a snapshot holds, field
discovery), :mod:`.panels` (panel availability and PNG drawings), :mod:`.page` (the HTML page),
:mod:`.server` (HTTP server, observer entry), :mod:`.__main__` (command line).
"""
from .live import LiveSource, RunEnded, RunNotFound, resolve_run
from .server import DEFAULT_PORT, DashboardServer, observe, serve

__all__ = ["LiveSource", "RunEnded", "RunNotFound", "resolve_run", "DashboardServer", "observe", "serve",
           "DEFAULT_PORT"]
