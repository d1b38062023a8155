"""Accuracy of the perception stage on the default scene against an exact ray cast.

Run: ``python bench/perception_accuracy.py [frames]`` (from the repository root; default 4 frames). Runs the
default scenario in-process with the mock renderer at full resolution (the GL renderer writes the same
bytes; the mock needs no GPU), both samplers, accuracy every frame on every beam (``accuracy_beams: 0``; a
run samples 4096 beams per evaluation by default), and prints Markdown: the range-error
table by distance band and the offloading measures. Writes the standalone reports to
``bench/out/perception_accuracy_<label>_<sampler>.{md,json}``. A third run uses a mount that sees past the
auger tube (:data:`ALT_MOUNT`) for the impact and coverage figures.
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cosim.runtime.inprocess import simulate  # noqa: E402
from cosim.scenario.config import Scenario  # noqa: E402
from perception_proc.accuracy_report import render_markdown, write_report  # noqa: E402
from perception_proc.summary import summarize  # noqa: E402

#: a mount that sees past the auger tube: behind the auger pivot, looking left and forward (from the default
#: auger-side mast the tube and spout hide the falling stream)
ALT_MOUNT = {"parent": "combine", "xyz_m": [-4.0, 1.5, 6.0], "rpy_deg": [0.0, 45.0, 75.0]}


def run(sampler: str, frames: int, mount: dict | None = None) -> dict:
    doc = {"format_version": 1, "renderer": "mock", "render": {"mock_scale": 1.0},
           "perception": {"accuracy_every_frames": 1, "accuracy_beams": 0, "sampler": sampler}}
    if mount is not None:
        doc["sensor"] = {"mount": mount}
    sc = Scenario.model_validate_json(json.dumps(doc))
    t0 = time.perf_counter()
    res = simulate(sc, frames=frames)
    wall = time.perf_counter() - t0
    rec = res.recorder
    series = {k: v for k, v in rec.series().items() if k.startswith("perc_state.")}
    seg = res.segment
    out = summarize(sc, series, seg.view("heightmap_truth"), seg.view("heightmap_perceived"))["perception"]
    out["wall_s"] = wall
    return out


def main() -> None:
    frames = int(sys.argv[1]) if len(sys.argv) > 1 else 4
    for label, sampler, mount in (("default", "planar", None), ("default", "nearest", None),
                                  ("alt_mount", "planar", ALT_MOUNT)):
        sec = run(sampler, frames, mount)
        where = "default mount" if mount is None else f"mount {mount['xyz_m']} rpy {mount['rpy_deg']}"
        print(render_markdown(sec, title=f"Default scene, {where}, sampler `{sampler}`, {frames} frames "
                                         f"(wall {sec['wall_s']:.0f} s with the mock renderer)"))
        write_report(sec, ROOT / "bench" / "out", stem=f"perception_accuracy_{label}_{sampler}")


if __name__ == "__main__":
    main()
