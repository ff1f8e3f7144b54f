"""The docs' relative links resolve: every ``[text](path)`` and ``[text](path#anchor)`` in README.md, under docs/
(its generated reports too) and in the model cards names a file of the checkout and, with an anchor, a heading of that
Markdown file (GitHub's anchors)."""
from __future__ import annotations

import re
import unicodedata
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
FENCE = re.compile(r"^(```|~~~)")


def markdown_files() -> list[Path]:
    """The Markdown a reader of the checkout follows links in."""
    found = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md")), *sorted((ROOT / "resources").rglob("*.md"))]
    return [path for path in found if path.is_file()]


def prose_lines(path: Path) -> list[str]:
    """The file's lines outside fenced code blocks."""
    lines, fenced = [], False
    for line in path.read_text(encoding="utf-8").splitlines():
        if FENCE.match(line.strip()):
            fenced = not fenced
        elif not fenced:
            lines.append(line)
    return lines


def github_anchor(heading: str) -> str:
    """GitHub's anchor for a heading's text: lower case, inline markup and punctuation dropped (letters, marks, decimal
    digits, underscores and hyphens kept), spaces made hyphens."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading).replace("`", "").lower()
    kept = "".join(ch for ch in text if ch in " -_" or unicodedata.category(ch)[0] in "LM"
                   or unicodedata.category(ch) == "Nd")
    return kept.replace(" ", "-")


def anchors_of(path: Path) -> set[str]:
    """Every heading's anchor in a Markdown file, repeats numbered as GitHub numbers them (``a``, ``a-1``, ...)."""
    anchors: set[str] = set()
    counts: dict[str, int] = {}
    for line in prose_lines(path):
        match = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if not match:
            continue
        anchor = github_anchor(match.group(1))
        seen = counts.get(anchor, 0)
        anchors.add(anchor if seen == 0 else f"{anchor}-{seen}")
        counts[anchor] = seen + 1
    return anchors


def broken_links(path: Path) -> list[str]:
    """The relative links of one file that name no file of the checkout, or no heading of the file they name."""
    broken = []
    for line in prose_lines(path):
        for target in LINK.findall(line):
            if re.match(r"^[a-z][a-z0-9+.-]*:", target):  # http:, https:, mailto:
                continue
            file_part, _, anchor = target.partition("#")
            linked = (path.parent / file_part).resolve() if file_part else path
            if not linked.exists():
                broken.append(f"{target}: no such file")
            elif anchor and linked.suffix == ".md" and anchor not in anchors_of(linked):
                broken.append(f"{target}: no heading with that anchor in {linked.name}")
    return broken


def test_github_anchor_follows_githubs_rules():
    assert github_anchor("Targets (issue 12), checked by `volsr_core.apps.bench.report.check_targets`") == \
        "targets-issue-12-checked-by-volsr_coreappsbenchreportcheck_targets"
    assert github_anchor("Depth slabs: `render(..., slabs=K)`") == "depth-slabs-render-slabsk"
    assert github_anchor("Where the history lives: at half the output size (2026-11-26)") == \
        "where-the-history-lives-at-half-the-output-size-2026-11-26"
    assert github_anchor("512², 2°/frame") == "512-2frame"


def test_a_broken_link_is_found(tmp_path):
    (tmp_path / "a.md").write_text("# A title\n[ok](#a-title) [bad](#no-title) [gone](missing.md)\n"
                                   "```\n[in code](nowhere.md)\n```\n", encoding="utf-8")
    assert broken_links(tmp_path / "a.md") == ["#no-title: no heading with that anchor in a.md",
                                               "missing.md: no such file"]


@pytest.mark.parametrize("path", markdown_files(), ids=lambda path: str(path.relative_to(ROOT)))
def test_relative_links_resolve(path):
    assert broken_links(path) == [], f"{path.relative_to(ROOT)}: broken links"
