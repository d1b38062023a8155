"""bench/HISTORY.md opens with an index by topic: every dated section (``## `` heading) is linked from it exactly
once, and every link of the index names a heading of the page (GitHub's slugs, tests/test_docs_links.py)."""
from __future__ import annotations

import re
from pathlib import Path

from test_docs_links import anchors

PAGE = Path(__file__).resolve().parent.parent / "bench" / "HISTORY.md"
INDEX = "Index"


def index_and_sections(text: str) -> tuple[list[str], list[str]]:
    """(the anchors the index links to, the anchors of the page's ``## `` sections other than the index)."""
    start = text.index(f"\n## {INDEX}\n")
    end = text.index("\n## ", start + 1)
    links = re.findall(r"\]\(#([^)]+)\)", text[start:end])
    sections = [a for a in _ordered_anchors(text) if a != INDEX.lower()]
    return links, sections


def _ordered_anchors(text: str) -> list[str]:
    heads = re.findall(r"^## (.+)$", text, re.M)
    return [re.sub(r"[^\w\- ]", "", h.strip().lower()).replace(" ", "-") for h in heads]


def test_every_section_is_in_the_index_once():
    text = PAGE.read_text(encoding="utf-8")
    links, sections = index_and_sections(text)
    assert len(sections) >= 40
    assert sorted(links) == sorted(sections), (
        f"not in the index: {sorted(set(sections) - set(links))}; linked twice or to nothing: "
        f"{sorted(a for a in links if links.count(a) > 1 or a not in sections)}")
    assert set(links) <= anchors(text)


def test_a_missing_section_is_found():
    text = "intro\n\n## Index\n\n* a:\n  * [x](#one)\n\n## One\n\nx\n\n## Two\n\ny\n"
    links, sections = index_and_sections(text)
    assert links == ["one"] and sections == ["one", "two"]
