"""The documentation stands alone: every file it links or names is in the repository, and it cites
no design notes outside it and no issue numbers."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PAGES = sorted((ROOT / "docs").glob("*.md")) + [ROOT / "README.md"]

LINK = re.compile(r"\]\(([^)#\s]+)(?:#[^)]*)?\)")
# Repository paths named in text: docs/x.md, examples/x.yaml, examples/meshes/x.msh, tests/x.py, ...
NAMED_PATH = re.compile(r"(?<![\w./-])((?:docs|examples|tests|benchmarks|jobs|scripts|pdemfem)/[\w./-]*\.(?:md|yaml|py|geo|msh|stl|png|sh))\b")
CITATION = re.compile(r"DESIGN\.md|(?<![\w&])#\d+\b|\bthe issue\b|\bissue #?\d+", re.IGNORECASE)


def _relative(page: Path):
    return page.relative_to(ROOT)


@pytest.mark.parametrize("page", PAGES, ids=lambda page: str(_relative(page)))
def test_links_and_named_files_exist(page):
    text = page.read_text()
    missing = []
    for target in LINK.findall(text):
        if "://" in target or target.startswith("mailto:"):
            continue
        if not (page.parent / target).exists():
            missing.append(target)
    for named in NAMED_PATH.findall(text):
        if "<" in named or "*" in named:
            continue
        if not (ROOT / named).exists() and not (page.parent / named).exists():
            missing.append(named)
    assert missing == [], f"{_relative(page)} names files that are not in the repository: {missing}"


@pytest.mark.parametrize("page", PAGES, ids=lambda page: str(_relative(page)))
def test_no_citations_outside_the_repository(page):
    found = [match.group(0) for match in CITATION.finditer(page.read_text())]
    assert found == [], f"{_relative(page)} cites what a reader cannot open: {found}"


def test_every_doc_page_is_in_the_readme_index():
    readme = (ROOT / "README.md").read_text()
    unlisted = [page.name for page in sorted((ROOT / "docs").glob("*.md")) if f"(docs/{page.name})" not in readme]
    assert unlisted == []
