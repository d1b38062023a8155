"""bench/HISTORY.md opens with an index by topic (bench/history_index.py writes it): current, every dated
section (``## `` heading) linked exactly once, and every link naming a heading of the page (GitHub's slugs,
tests/test_docs_links.py)."""
from __future__ import annotations

import re
import sys
from pathlib import Path

from test_docs_links import anchors

BENCH = Path(__file__).resolve().parent.parent / "bench"
if str(BENCH) not in sys.path:
    sys.path.insert(0, str(BENCH))

from history_index import INDEX, PAGE, index_text, slug, with_index  # noqa: E402


def test_the_index_is_current():
    text = PAGE.read_text(encoding="utf-8")
    assert with_index(text) == text, "bench/HISTORY.md's index is stale: python bench/history_index.py"


def test_every_section_is_in_the_index_once_and_every_link_lands():
    text = PAGE.read_text(encoding="utf-8")
    links = re.findall(r"\]\(#([^)]+)\)", index_text(text))
    sections = [slug(h) for h in re.findall(r"^## (.+)$", text, re.M) if h.strip() != INDEX]
    assert len(sections) >= 40
    assert sorted(links) == sorted(sections)
    assert set(links) <= anchors(text)


def test_a_new_section_lands_under_its_topic_or_other():
    text = "intro\n\n## 2026-12-01: sweeps on Dask again\n\nx\n\n## 2026-12-01: something new\n\ny\n"
    out = with_index(text)
    assert out.index("## Index") < out.index("## 2026-12-01: sweeps")
    assert "* Studies and sweeps:\n  * [2026-12-01: sweeps on Dask again](#2026-12-01-sweeps-on-dask-again)" in out
    assert "* Other:\n  * [2026-12-01: something new](#2026-12-01-something-new)" in out
    assert with_index(out) == out
