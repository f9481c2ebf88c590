"""The project's markdown links resolve: every relative link names a file of the tree, and every
``#anchor`` a heading of its target, as GitHub renders it. The README and the learned
controllers' study (docs/learned/study.md) point into each other, so a renamed heading or a
moved page shows here rather than as a dead link."""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = sorted(
    [
        ROOT / "README.md",
        ROOT / "CONTRIBUTING.md",
        ROOT / "firmware" / "README.md",
        *(ROOT / "docs").rglob("*.md"),
        *(ROOT / "policies" / "agents").glob("*/MODEL_CARD.md"),
    ]
)
FENCE = re.compile(r"```.*?```", re.S)
LINK = re.compile(r"\]\(([^)\s]+)\)")
HEADING = re.compile(r"^#+ (.+)$", re.M)


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped, spaces to hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def anchors(page: Path) -> set[str]:
    """The anchors of a markdown page's headings (those inside code blocks are not headings)."""
    return {slug(h) for h in HEADING.findall(FENCE.sub("", page.read_text()))}


def links(page: Path) -> list[str]:
    """The page's relative link targets (code blocks and web addresses left out)."""
    found = LINK.findall(FENCE.sub("", page.read_text()))
    return [t for t in found if not re.match(r"[a-z]+:", t)]


def test_slug_is_githubs() -> None:
    assert slug("Learned controller (PPO)") == "learned-controller-ppo"
    assert slug("The robot's numbers") == "the-robots-numbers"
    assert slug("The world: obstacles, occlusion") == "the-world-obstacles-occlusion"


def test_the_pages_have_links_to_check() -> None:
    """The check below is not vacuous: the README links into docs/ and the study back."""
    assert ROOT / "docs" / "learned" / "study.md" in PAGES
    assert "docs/learned/study.md" in links(ROOT / "README.md")
    assert "../../README.md#learned-controller-ppo" in links(ROOT / "docs/learned/study.md")


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_resolves(page: Path) -> None:
    broken = []
    for target in links(page):
        path, _, anchor = target.partition("#")
        file = (page.parent / path).resolve() if path else page
        if not file.exists():
            broken.append(f"{target}: no such file")
        elif anchor and file.suffix == ".md" and anchor not in anchors(file):
            broken.append(f"{target}: no heading #{anchor} in {file.relative_to(ROOT)}")
    assert not broken, f"{page.relative_to(ROOT)}: " + "; ".join(broken)


# Names of the project's modules, classes and functions written in backticks: a module moved
# or a function renamed shows here rather than as an ImportError in a reader's session.
PROJECT_NAME = re.compile(
    r"`((?:follow_env|policies|eval|train|bridge|execution|bench)(?:\.[A-Za-z_]\w*)+)"
)


def _resolves(name: str) -> bool:
    parts = name.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        for attr in parts[cut:]:
            if not hasattr(obj, attr):
                return False
            obj = getattr(obj, attr)
        return True
    return False


def test_the_project_names_the_pages_give_exist() -> None:
    names = {(m, page.name) for page in PAGES for m in PROJECT_NAME.findall(page.read_text())}
    assert len(names) > 20, "the pattern no longer finds the pages' names"
    missing = sorted(f"{name} ({page})" for name, page in names if not _resolves(name))
    assert not missing, missing
