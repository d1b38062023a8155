"""Live Foxglove: a running co-simulation served over the Foxglove WebSocket protocol (foxglove-sdk).

``launch.py run --foxglove [--foxglove-port N]`` starts :func:`cosim.foxglove.live.observe` as an observer of
the run; :mod:`.scene` turns the render scene into Foxglove scene entities; ``layout.json`` (next to this file,
:data:`LAYOUT`) is a Foxglove layout for the run's panels. See docs/foxglove.md.
"""
from pathlib import Path

__all__ = ["LAYOUT"]

#: the Foxglove / Lichtblick layout file shipped with the package
LAYOUT = Path(__file__).with_name("layout.json")
