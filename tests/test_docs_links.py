"""Every relative link in the repository's Markdown pages resolves to a file inside the repository, every
``#anchor`` names a heading of its page (GitHub's slugs), and nothing points outside it (the design contract the
project was built from is not part of the repository)."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), ROOT / "bench" / "README.md",
         *sorted((ROOT / "examples").glob("*/README.md"))]
#: [text](target) and [text](target "title"); images too
_LINK = re.compile(r"!?\[[^\]]*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
_EXTERNAL = ("http://", "https://", "mailto:")
_HEADING = re.compile(r"^#{1,6}[ \t]+(.*?)[ \t]*#*[ \t]*$", re.M)


def _prose(page: Path) -> str:
    return re.sub(r"```.*?```", "", page.read_text(), flags=re.S)


def anchors(text: str) -> set[str]:
    """The ``#anchor`` names GitHub gives the headings of Markdown ``text``: lower case, links reduced to their
    text, punctuation but ``-`` and ``_`` dropped, spaces to ``-``; a repeated heading gets ``-1``, ``-2``, ..."""
    seen: dict[str, int] = {}
    out = set()
    for m in _HEADING.finditer(re.sub(r"```.*?```", "", text, flags=re.S)):
        title = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", m.group(1)).strip().lower()
        slug = re.sub(r"[^\w\- ]", "", title).replace(" ", "-")
        n = seen.get(slug, 0)
        seen[slug] = n + 1
        out.add(slug if n == 0 else f"{slug}-{n}")
    return out


def broken_anchors(page: Path) -> list[str]:
    """The links of ``page`` whose ``#anchor`` names no heading of the Markdown page they point at."""
    bad = []
    for target in links(page):
        if target.startswith(_EXTERNAL) or "#" not in target:
            continue
        file, frag = target.split("#", 1)
        dest = (page.parent / file).resolve() if file else page
        if dest.suffix == ".md" and dest.exists() and frag not in anchors(dest.read_text()):
            bad.append(target)
    return bad


def links(page: Path) -> list[str]:
    return [m.group(1) for m in _LINK.finditer(_prose(page))]  # code blocks hold no links


def test_the_pages_have_links_to_check():
    assert sum(len(links(p)) for p in PAGES) >= 5
    assert ROOT / "docs" / "architecture.md" in PAGES


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_resolve_inside_the_repository(page):
    bad = []
    for target in links(page):
        if target.startswith(_EXTERNAL) or target.startswith("#"):
            continue
        path = (page.parent / target.split("#", 1)[0]).resolve()
        if not path.is_relative_to(ROOT) or not path.exists():
            bad.append(target)
    assert bad == [], f"{page.name}: links that do not resolve to a file in the repository: {bad}"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_anchors_name_a_heading_of_their_page(page):
    assert broken_anchors(page) == [], f"{page.name}: anchors that name no heading"


def test_the_anchor_check_follows_githubs_slugs(tmp_path):
    other = tmp_path / "other.md"
    other.write_text("# Title\n\n## Outputs: `summary.json` and [figures](x.md)\n\n## Notes\n\n## Notes\n"
                     "```\n# not a heading\n```\n")
    assert anchors(other.read_text()) == {"title", "outputs-summaryjson-and-figures", "notes", "notes-1"}
    page = tmp_path / "page.md"
    page.write_text("[a](other.md#notes-1) [b](other.md#outputs-summaryjson-and-figures) [c](#here)\n\n# Here\n"
                    "[d](other.md#not-a-heading) [e](#nowhere) [f](other.md)\n")
    assert broken_anchors(page) == ["other.md#not-a-heading", "#nowhere"]


#: citations of files that are not in the repository (the team's design notes), of an issue tracker's numbers or of
#: the team's working sessions
_OUTSIDE = re.compile(r"\b(?:DESIGN|STYLE)\.md\b|\.\./shared/|/work/shared\b|\bissues? #?\d+|\bsession \d+\b", re.I)


def tracked_text_files() -> list[Path]:
    import subprocess
    out = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=False).stdout.split()
    keep = (".py", ".md", ".yaml", ".yml", ".json", ".glsl", ".frag", ".vert", ".geom", ".toml", ".txt", ".html")
    # bench/HISTORY.md, the dated log, is held to the same rule: a clone has nothing else to follow
    return [ROOT / f for f in out if f.endswith(keep) and f != "tests/test_docs_links.py"]


def test_nothing_in_the_repository_cites_files_outside_it():
    files = tracked_text_files()
    if not files:
        pytest.skip("not a git checkout")
    hits = []
    for f in files:
        for n, line in enumerate(f.read_text(errors="replace").splitlines(), 1):
            if _OUTSIDE.search(line):
                hits.append(f"{f.relative_to(ROOT)}:{n}: {line.strip()[:80]}")
    assert hits == [], "citations a user who clones the project cannot follow:\n" + "\n".join(hits)
