"""The index by topic at the top of bench/HISTORY.md, generated from its dated ``## `` headings: each heading is
listed under the first topic whose pattern it matches (:data:`TOPICS`), else under "Other", in page order.

    python bench/history_index.py          # rewrite the index in place (after adding a section)
"""
from __future__ import annotations

import re
import sys
from pathlib import Path

__all__ = ["PAGE", "INDEX", "TOPICS", "slug", "index_text", "with_index"]

PAGE = Path(__file__).resolve().parent / "HISTORY.md"
#: the index's own heading
INDEX = "Index"
#: topic -> a pattern of the headings under it (the first topic that matches wins)
TOPICS: dict[str, str] = {
    "Headline figures and end to end": r"run_all|quiet re-measure|wall-time target|ratio again|20x|default run end to "
                                       r"end|End to end, default|GPU machine|[Uu]nder load",
    "Perception": r"perception step|cart search|perception frame's CPU|^Perception$|19 cm beam|degenerate "
                  r"frames",
    "Renderer, LiDAR and the mock": r"renderer's and the dynamics'|beam-native|mock renderer|mock as the fast|Renderer "
                                    r"\(renderer_proc",
    "Dynamics, control and FMUs": r"^Dynamics: measured|fused estimator|FMUs in the loop|controller",
    "Field conditions and sensors": r"field-conditions|field suite|cameras and several sensors|dust",
    "Runtime, harness and interfaces": r"harness with named|fork server|input checks|pipelined schedule|validate and a 5 s run|launcher "
                                       r"back|Lockstep ring|reliability|liveness|cost grows|Python API|plug-in seams",
    "Observers: viewer, recording, Foxglove": r"dashboard|Foxglove|Viewer and recording",
    "Studies and sweeps": r"sweeps? on Dask|study",
    "Retired scripts": r"Retired scripts",
}


def slug(heading: str) -> str:
    """GitHub's anchor of a heading (tests/test_docs_links.py's rule, without the repeat counter)."""
    title = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading).strip().lower()
    return re.sub(r"[^\w\- ]", "", title).replace(" ", "-")


def _sections(text: str) -> list[str]:
    return [h for h in re.findall(r"^## (.+)$", text, re.M) if h.strip() != INDEX]


def index_text(text: str) -> str:
    """The index section (from its heading to the blank line before the next section) for the page ``text``."""
    groups: dict[str, list[str]] = {t: [] for t in [*TOPICS, "Other"]}
    for h in _sections(text):
        topic = next((t for t, rx in TOPICS.items() if re.search(rx, h)), "Other")
        groups[topic].append(h)
    lines = [f"## {INDEX}", "", "The sections below by topic, newest first within each (one link per dated "
             "heading; `python bench/history_index.py` writes this index).", ""]
    for topic, heads in groups.items():
        if heads:
            lines.append(f"* {topic}:")
            lines += [f"  * [{' '.join(h.replace('[', '').replace(']', '').replace('`', '').split())}](#{slug(h)})"
                      for h in heads]
    return "\n".join(lines) + "\n\n"


def with_index(text: str) -> str:
    """``text`` with its index replaced by (or, without one, given before the first section) :func:`index_text`."""
    start = text.find(f"\n## {INDEX}\n")
    if start >= 0:
        end = text.index("\n## ", start + 1) + 1
        return text[:start + 1] + index_text(text) + text[end:]
    first = text.index("\n## ") + 1
    return text[:first] + index_text(text) + text[first:]


if __name__ == "__main__":
    page = Path(sys.argv[1]) if len(sys.argv) > 1 else PAGE
    page.write_text(with_index(page.read_text(encoding="utf-8")), encoding="utf-8")
    print(page)
