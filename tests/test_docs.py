"""The README and docs/ hold together: every relative link reaches a file (and a heading), docs/index.md lists every
page, and the README stays a ten-minute read."""

from __future__ import annotations

import re
from pathlib import Path
from urllib.parse import unquote

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
README_LIMIT = 15_000  # characters: DESIGN.md's "a README read in ten minutes"

FENCE = re.compile(r"^(```|~~~).*?^\1[^\n]*$", re.M | re.S)
INLINE_CODE = re.compile(r"`+[^`\n]*`+")
# [text](target) and ![alt](target), the text may hold one level of brackets; an optional "title" after the target
LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^()\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
HEADING = re.compile(r"^ {0,3}(#{1,6})[ \t]+(.*?)(?:[ \t]+#+)?[ \t]*$", re.M)


def pages() -> list[Path]:
    """The markdown pages whose links are checked: the README and every page of docs/."""
    return [ROOT / "README.md", *sorted(DOCS.glob("*.md"))]


def without_code(text: str) -> str:
    """The text with fenced blocks removed and inline code spans blanked (neither holds links or headings)."""
    return INLINE_CODE.sub("code", FENCE.sub("", text))


def github_slug(heading: str) -> str:
    """The anchor GitHub gives a heading: its rendered text (code spans' content kept, a link's text kept), lower
    case, every character but letters, digits, spaces, hyphens and underscores dropped, spaces turned into hyphens."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading)
    text = text.replace("`", "").lower()
    text = "".join(char for char in text if char.isalnum() or char in " -_")
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    """Every heading anchor of a markdown file, repeated headings numbered as GitHub numbers them (-1, -2, ...)."""
    text = FENCE.sub("", path.read_text())
    seen: dict[str, int] = {}
    found = set()
    for match in HEADING.finditer(text):
        slug = github_slug(match.group(2).strip())
        count = seen.get(slug, 0)
        seen[slug] = count + 1
        found.add(slug if count == 0 else f"{slug}-{count}")
    return found


def relative_links(path: Path) -> list[str]:
    """The link targets of a page that are not URLs (no scheme such as https: or mailto:)."""
    targets = LINK.findall(without_code(path.read_text()))
    return [target for target in targets if not re.match(r"^[a-zA-Z][a-zA-Z0-9+.-]*:", target)]


def shown(path: Path) -> str:
    """A path as a message names it: relative to the repository where it lies inside it."""
    return str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path)


def broken_links(path: Path) -> list[str]:
    """The relative links of ``path`` that reach no file, or no heading of the markdown file they name."""
    broken = []
    for target in relative_links(path):
        file_part, _, anchor = target.partition("#")
        linked = (path.parent / unquote(file_part)).resolve() if file_part else path
        if not linked.exists():
            broken.append(f"{target}: no file {shown(linked)}")
        elif anchor and linked.suffix == ".md" and anchor not in anchors(linked):
            broken.append(f"{target}: no heading #{anchor} in {shown(linked)}")
    return broken


def test_github_slugs_of_the_kinds_of_headings_these_pages_use() -> None:
    assert github_slug("Parity with memory-gym 1.0.2") == "parity-with-memory-gym-102"
    assert github_slug("Configs and `--set`") == "configs-and---set"
    assert github_slug("Logging: TensorBoard, `training.csv`, Weights & Biases") == (
        "logging-tensorboard-trainingcsv-weights--biases"
    )
    assert github_slug("HELM (`model.helm`)") == "helm-modelhelm"
    assert github_slug("See [the docs](docs/index.md)") == "see-the-docs"


def test_a_broken_link_and_a_missing_heading_are_found(tmp_path: Path) -> None:
    (tmp_path / "other.md").write_text("# Title\n\n## Part two\n\n## Part two\n")
    page = tmp_path / "page.md"
    page.write_text(
        "[ok](other.md#part-two) [second](other.md#part-two-1) [self](#here) [web](https://example.org/x)\n"
        "[gone](missing.md) [no heading](other.md#part-three) `[in code](missing_too.md)`\n\n"
        "```\n[in a block](missing_three.md)\n```\n\n## Here\n"
    )
    assert [entry.split(":")[0] for entry in broken_links(page)] == ["missing.md", "other.md#part-three"]


@pytest.mark.parametrize("page", pages(), ids=lambda path: str(path.relative_to(ROOT)))
def test_every_relative_link_reaches_a_file_and_heading(page: Path) -> None:
    assert broken_links(page) == []


def test_the_docs_index_links_every_page() -> None:
    linked = {(DOCS / target.partition("#")[0]).resolve() for target in relative_links(DOCS / "index.md")}
    unlinked = [path.name for path in sorted(DOCS.glob("*.md")) if path.name != "index.md" and path not in linked]
    assert unlinked == [], f"docs/index.md does not link {unlinked}"


def test_the_readme_links_the_docs_index() -> None:
    assert "docs/index.md" in relative_links(ROOT / "README.md")


def test_the_readme_is_a_ten_minute_read() -> None:
    size = len((ROOT / "README.md").read_text())
    assert size <= README_LIMIT, f"README.md has {size} characters, more than {README_LIMIT}"
