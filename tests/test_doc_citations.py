"""Code cites the documentation by page anchor (``docs/decisions.md#synthesis-smoothing``); a renamed heading must
not leave a citation pointing nowhere. Section numbers (``RESULTS §13``) are not used at all."""

import re
import subprocess
from pathlib import Path

from markdown.extensions.toc import slugify

REPO = Path(__file__).resolve().parents[1]
CITATION = re.compile(r"((?:docs/[\w./-]+\.md|bench/RESULTS\.md|README\.md))#([\w-]+)")
SECTION_NUMBER = re.compile(r"(RESULTS|README)(\.md)?,? §\s*\d")


def _anchors(page: Path) -> set[str]:
    """The anchors MkDocs (and GitHub) make from the page's headings, outside code fences."""
    anchors, fence = set(), False
    for line in page.read_text().splitlines():
        if line.startswith("```"):
            fence = not fence
            continue
        heading = None if fence else re.match(r"#{1,6}\s+(.*?)\s*(\{#([\w-]+)\})?\s*$", line)
        if heading:
            anchors.add(heading.group(3) or slugify(heading.group(1).replace("`", ""), "-"))
    return anchors


def _cited_files() -> list[Path]:
    listed = subprocess.run(
        ["git", "ls-files", "-co", "--exclude-standard", "mocapkit", "configs", "scripts", "bench"],
        capture_output=True,
        text=True,
        cwd=REPO,
        check=True,
    ).stdout.split()
    return [REPO / f for f in listed if f.endswith((".py", ".yaml", ".md")) and (REPO / f).exists()]


def test_every_cited_anchor_exists():
    bad, count = [], 0
    for path in _cited_files():
        for match in CITATION.finditer(path.read_text()):
            count += 1
            page = REPO / match.group(1)
            if not page.is_file() or match.group(2) not in _anchors(page):
                bad.append(f"{path.relative_to(REPO)}: {match.group(0)}")
    assert count > 20, "the code should cite the docs by anchor"
    assert not bad, "citations of missing pages or anchors:\n" + "\n".join(bad)


def test_no_citation_by_section_number():
    bad = [str(p.relative_to(REPO)) for p in _cited_files() if SECTION_NUMBER.search(p.read_text())]
    assert not bad, "cite a page anchor, not a section number: " + ", ".join(bad)
