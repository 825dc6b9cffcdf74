"""The documentation's links resolve: every relative Markdown link of README.md, CHANGELOG.md and docs/, and every
``docs/...`` path named (or built as ``"docs" / ...``) in them or in the code (lfmbench/, render_tools/, benchmarks/, tests/, the Makefile), names
a file or folder of the repository; and every page of docs/ is reachable from the manual's index."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: Markdown files whose relative links are checked.
PAGES = sorted([ROOT / "README.md", ROOT / "CHANGELOG.md", *(ROOT / "docs").rglob("*.md")])
#: Where ``docs/...`` paths are looked for besides the pages.
CODE = sorted([*(ROOT / "lfmbench").rglob("*.py"), *(ROOT / "render_tools").rglob("*.py"),
               *(ROOT / "benchmarks").rglob("*.py"), *(ROOT / "tests").rglob("*.py"),
               *(ROOT / "lfmbench").rglob("*.yaml"), *(ROOT / "render_tools").rglob("*.yaml"), ROOT / "Makefile"])
CODE.remove(Path(__file__).resolve())  # its own examples of broken paths
#: ``[text](target)`` and ``![alt](target)``; the target up to a space, ``)`` or ``#``.
LINK = re.compile(r"\]\(([^)\s#]*)(#[^)\s]*)?\)")
#: A path under docs/ as written in prose or code: docs/<dir>/<name>.<ext> or docs/<name>.md (a trailing
#: ``/`` or ``*`` glob is a folder or a pattern, not checked).
DOC_PATH = re.compile(r"(?<![\w./-])docs/[\w./-]*\w\.(?:md|png|json)\b")
#: A path built in code: ``"docs" / "guide" / "datasets.md"``.
DOC_JOIN = re.compile(r'"docs"((?:\s*/\s*"[\w.-]+")+)')


def _links(page: Path) -> list[tuple[int, str]]:
    out, fence = [], False
    for n, line in enumerate(page.read_text(encoding="utf-8").splitlines(), 1):
        if line.lstrip().startswith("```"):
            fence = not fence
            continue
        if not fence:
            out += [(n, m.group(1)) for m in LINK.finditer(line)]
    return out


def _relative(target: str) -> bool:
    return bool(target) and not re.match(r"^[a-z][a-z0-9+.-]*:", target)   # no http:, mailto:, ...


def test_pages_exist():
    assert (ROOT / "docs" / "README.md") in PAGES and (ROOT / "CHANGELOG.md").is_file()


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_resolve(page):
    broken = [f"line {n}: {t}" for n, t in _links(page) if _relative(t) and not (page.parent / t).exists()]
    assert broken == [], f"{page.relative_to(ROOT)}: links to missing files"


def test_named_docs_paths_exist():
    """A ``docs/...`` path written anywhere (prose, code comments, docstrings) names a file that exists."""
    missing = set()
    for f in [*PAGES, *CODE]:
        text = f.read_text(encoding="utf-8")
        named = [m.group(0) for m in DOC_PATH.finditer(text)]
        named += ["docs/" + "/".join(re.findall(r'"([\w.-]+)"', m.group(1))) for m in DOC_JOIN.finditer(text)]
        missing.update(f"{f.relative_to(ROOT)}: {p}" for p in named if p.endswith((".md", ".png", ".json"))
                       and not (ROOT / p).exists())
    assert sorted(missing) == []


def test_every_page_is_reachable_from_the_index():
    """Every page under docs/ is linked from docs/README.md or from a page it links to (no orphan page)."""
    seen, todo = set(), [ROOT / "docs" / "README.md"]
    while todo:
        page = todo.pop()
        if page in seen or page.suffix != ".md" or not page.is_file():
            continue
        seen.add(page)
        todo += [(page.parent / t).resolve() for _, t in _links(page) if _relative(t)]
    orphans = [str(p.relative_to(ROOT)) for p in (ROOT / "docs").rglob("*.md") if p.resolve() not in seen]
    assert orphans == []


def test_the_checker_finds_a_broken_link(tmp_path):
    """The link pattern sees links, images and anchors, and skips URLs and fenced code."""
    page = tmp_path / "p.md"
    page.write_text("[a](missing.md) ![b](img/x.png) [c](https://x.org/y) [d](p.md#top)\n```\n[e](in_code.md)\n```\n")
    assert [t for _, t in _links(page) if _relative(t)] == ["missing.md", "img/x.png", "p.md"]
    assert DOC_PATH.findall("see docs/guide/metrics.md, docs/img/*.png and `docs/benchmarks/render.json`") == [
        "docs/guide/metrics.md", "docs/benchmarks/render.json"]
    assert DOC_JOIN.search('ROOT / "docs" / "guide" / "x.md"').group(1) == ' / "guide" / "x.md"'


def test_benchmark_pages_link_images_from_their_folder():
    """Benchmark scripts write pages into docs/benchmarks/ and figures into docs/img/: an image link they write is
    ``../img/...`` (``img/...`` would resolve to docs/benchmarks/img/, which does not exist)."""
    bad = [f"{p.relative_to(ROOT)}:{n}" for p in sorted((ROOT / "benchmarks").rglob("*.py"))
           for n, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1) if re.search(r"\]\((img/|\{)", line)
           and "../" not in line]
    assert bad == []
