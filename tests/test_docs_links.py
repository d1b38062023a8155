"""Every relative link in README.md and docs/*.md resolves to a file inside the repository, and nothing points
outside it (the design contract the project was built from is not part of the repository)."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
#: [text](target) and [text](target "title"); images too
_LINK = re.compile(r"!?\[[^\]]*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
_EXTERNAL = ("http://", "https://", "mailto:")


def links(page: Path) -> list[str]:
    text = re.sub(r"```.*?```", "", page.read_text(), flags=re.S)  # code blocks hold no links
    return [m.group(1) for m in _LINK.finditer(text)]


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
def test_no_page_points_outside_the_repository(page):
    text = page.read_text()
    assert "../shared" not in text and "shared/DESIGN.md" not in text


#: citations of files that are not in the repository (the team's design notes) or of an issue tracker's numbers
_OUTSIDE = re.compile(r"\b(?:DESIGN|STYLE)\.md\b|\.\./shared/|\bissue \d+\b", re.I)


def tracked_text_files() -> list[Path]:
    import subprocess
    out = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=False).stdout.split()
    keep = (".py", ".md", ".yaml", ".yml", ".json", ".glsl", ".frag", ".vert", ".geom", ".toml", ".txt", ".html")
    # bench/HISTORY.md is the dated log: it names what each dated measurement was made for
    return [ROOT / f for f in out if f.endswith(keep) and f != "bench/HISTORY.md" and f != "tests/test_docs_links.py"]


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
