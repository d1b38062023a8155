"""Command line of the viewer.

    python -m cosim.viewer --attach RUN [--port 8765] [--host 127.0.0.1]   # RUN: run directory or segment name
    python -m cosim.viewer --attach RUN --once        # print one snapshot's summary as JSON and detach
    python -m cosim.viewer --replay FILE.mcap [--speed 1] [--loop]

Exit codes: 130 served until Ctrl-C or SIGTERM (as every verb of ``launch.py``), 0 ``--once`` done, 1 the run
does not exist or has ended (a clear message, no traceback), 2 bad usage or a port it cannot listen on.
"""
from __future__ import annotations

import argparse
import json
import logging
import os
import sys
from typing import Sequence

__all__ = ["main", "build_parser", "EXIT_NO_RUN", "EXIT_INTERRUPTED"]

EXIT_NO_RUN = 1
#: served until Ctrl-C or SIGTERM (the exit code of every interrupted verb)
EXIT_INTERRUPTED = 130


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m cosim.viewer",
                                description="Watch a running co-simulation, or replay a recording, in the browser")
    what = p.add_mutually_exclusive_group(required=True)
    what.add_argument("--attach", metavar="RUN", help="run directory (with run.json) or shared-memory segment name")
    what.add_argument("--replay", metavar="FILE", help="an MCAP recording written with launch.py run --record")
    p.add_argument("--port", type=int, default=8765, help="TCP port (0: any free port; default %(default)s)")
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default %(default)s, local only)")
    p.add_argument("--once", action="store_true", help="with --attach: print one snapshot as JSON, then detach")
    p.add_argument("--announce", metavar="FILE", help="write {\"url\": ...} to FILE once the server listens")
    p.add_argument("--speed", type=float, default=1.0, help="replay speed, x simulated time (default %(default)s)")
    p.add_argument("--loop", action="store_true", help="replay: start over at the end")
    return p


def _once(source) -> dict:
    from .server import state_json

    doc = state_json(source)
    return {"run": doc["run"], "segment": source.segment_name, "status": doc["status"], "frame": doc["frame"],
            "frames_planned": doc["frames_planned"], "t_s": doc["t_s"], "blocks": source.blocks,
            "panels": {k: v["available"] for k, v in doc["panels"].items()}}


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s")
    from .live import LiveSource, RunEnded, RunNotFound
    from .server import NICE, serve

    if args.replay:
        from cosim.recording import RecordingError
        from cosim.viewer.replay import ReplaySource

        try:
            source = ReplaySource(args.replay, speed=args.speed, loop=args.loop)
        except (FileNotFoundError, RecordingError, ValueError) as exc:
            sys.stderr.write(f"cannot replay {args.replay}: {exc}\n")
            return EXIT_NO_RUN
    else:
        try:
            source = LiveSource(args.attach)
        except (RunNotFound, RunEnded) as exc:
            sys.stderr.write(f"{exc}\n")
            return EXIT_NO_RUN
        if args.once:
            try:
                sys.stdout.write(json.dumps(_once(source)) + "\n")
            finally:
                source.close()
            return 0
        try:
            os.nice(NICE)
        except OSError:
            pass
    try:
        signalled = serve(source, args.host, args.port, args.announce)
    except KeyboardInterrupt:
        signalled = True
    except OSError as exc:
        source.close()
        sys.stderr.write(f"viewer cannot listen on {args.host}:{args.port}: {exc}\n")
        return 2
    if signalled:
        sys.stderr.write("interrupted\n")
        return EXIT_INTERRUPTED
    return 0


if __name__ == "__main__":
    sys.exit(main())
