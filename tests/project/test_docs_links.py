"""The front page, docs/ and the studies' logs hold together: every relative link and image resolves, every
`#anchor` names a heading, and README.md stays a short front page opening with the two commands."""
from __future__ import annotations

import re
from pathlib import Path

import pytest
from tests.helpers.paths import REPO as ROOT

README = ROOT / "README.md"
README_MAX_LINES = 300
SKIPPED_SCHEMES = ("http://", "https://", "mailto:")

_FENCE = re.compile(r"^\s*(```|~~~)")
_INLINE_CODE = re.compile(r"(`+)(?:(?!\1).)+?\1", re.DOTALL)
# [text](target) and ![alt](target); the target may be <...> and may carry a "title"
_MD_LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\[\]]*\])*\]\(\s*(<[^>]*>|[^)\s]*)(?:\s+[\"'][^)]*[\"'])?\s*\)")
_IMG_SRC = re.compile(r"<img\b[^>]*?\bsrc\s*=\s*[\"']([^\"']+)[\"']", re.IGNORECASE)
_HEADING = re.compile(r"^(#{1,6})\s+(.*?)\s*#*\s*$")


def doc_files() -> list[Path]:
    """The front page, docs/, the changelog and the studies' READMEs and logs (the results pages link
    into the logs, and the logs back into docs/)."""
    return [README, *sorted(ROOT.glob("CHANGELOG.md")), *sorted((ROOT / "docs").glob("*.md")),
            *sorted((ROOT / "studies").rglob("*.md"))]


def prose(text: str, blank_code: bool = True) -> str:
    """The text with fenced code blocks emptied and, unless told not to, inline code spans (which
    may run over lines within a paragraph) blanked; line numbers are kept."""
    lines, fenced = [], False
    for line in text.splitlines():
        if _FENCE.match(line):
            fenced = not fenced
            lines.append("")
        else:
            lines.append("" if fenced else line)
    out = "\n".join(lines)
    if blank_code:
        paragraphs = re.split(r"(\n[ \t]*\n)", out)
        out = "".join(_INLINE_CODE.sub(lambda m: "\n" * m.group(0).count("\n"), part) for part in paragraphs)
    return out


def find_links(text: str) -> list[tuple[int, str]]:
    """Every link and image target in Markdown text: (line number, target)."""
    body = prose(text)
    found = [(m.start(), m.group(1).strip("<>")) for m in _MD_LINK.finditer(body)]
    found += [(m.start(), m.group(1)) for m in _IMG_SRC.finditer(body)]
    return [(body.count("\n", 0, start) + 1, target) for start, target in sorted(found)]


def slug(heading: str) -> str:
    """The anchor a code host gives a heading: plain text, lower case, punctuation dropped,
    spaces to hyphens."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading)  # links -> their text
    text = re.sub(r"<[^>]+>", "", text).replace("`", "").strip().lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(text: str) -> set[str]:
    seen: dict[str, int] = {}
    out = set()
    for line in prose(text, blank_code=False).splitlines():
        match = _HEADING.match(line)
        if match:
            base = slug(match.group(2))
            n = seen.get(base, 0)
            seen[base] = n + 1
            out.add(base if n == 0 else f"{base}-{n}")
    return out


def broken_links(path: Path) -> list[str]:
    """'file:line: target (why)' for every relative link or image of `path` that does not resolve."""
    text = path.read_text(encoding="utf-8")
    problems = []
    for number, target in find_links(text):
        where = f"{path.name}:{number}: {target}"
        if not target or target.lower().startswith(SKIPPED_SCHEMES):
            continue
        if re.match(r"^[a-z][a-z0-9+.-]*:", target, re.IGNORECASE):  # another scheme: not a file
            continue
        file_part, _, anchor = target.partition("#")
        file_part = file_part.split("?", 1)[0]
        if not file_part:  # '#anchor' in the same file
            if anchor and anchor.lower() not in anchors(text):
                problems.append(f"{where} (no such heading)")
            continue
        resolved = (path.parent / file_part).resolve()
        if not resolved.exists():
            problems.append(f"{where} (no such file)")
        elif anchor and resolved.suffix == ".md" and resolved.is_file():
            if anchor.lower() not in anchors(resolved.read_text(encoding="utf-8")):
                problems.append(f"{where} (no such heading in {resolved.name})")
    return problems


@pytest.mark.parametrize("path", doc_files(), ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_and_image_resolves(path: Path) -> None:
    assert broken_links(path) == []


def test_the_checker_finds_broken_links(tmp_path: Path) -> None:
    (tmp_path / "exists.md").write_text("# Here\n\n## A section\n", encoding="utf-8")
    (tmp_path / "pic.png").write_bytes(b"")
    page = tmp_path / "page.md"
    page.write_text(
        "# Title\n\n## Local heading\n\n"
        "[fine](exists.md) [fine anchor](exists.md#a-section) ![fine](pic.png) [web](https://example.org/x)\n"
        "[mail](mailto:a@b.c) [here](#local-heading) <img src=\"pic.png\" width=\"10\">\n"
        "[gone](missing.md) ![gone image](img/nothing.png)\n"
        "<img alt=\"x\" src='nope.png'>\n"
        "[bad anchor](#nowhere) [bad remote anchor](exists.md#nowhere)\n"
        "`[not a link](in-code.md)` and `a code span\nover two lines [no](in-span.md)`\n"
        "[a link over\ntwo lines](gone-too.md)\n\n"
        "```\n[not a link either](in-fence.md)\n```\n",
        encoding="utf-8")
    problems = broken_links(page)
    assert [p.split(": ", 1)[1] for p in problems] == [
        "missing.md (no such file)", "img/nothing.png (no such file)", "nope.png (no such file)",
        "#nowhere (no such heading)", "exists.md#nowhere (no such heading in exists.md)",
        "gone-too.md (no such file)"]


def test_slugs_follow_the_code_host() -> None:
    assert slug("Today: `make demo` (paired, with intervals)") == "today-make-demo-paired-with-intervals"
    assert slug("Synthetic data in the 3D-RecGAN++ geometry") == "synthetic-data-in-the-3d-recgan-geometry"
    assert slug("The CPU transfer experiment (`completion_cpu`)") == "the-cpu-transfer-experiment-completion_cpu"


def test_readme_is_a_short_front_page() -> None:
    lines = README.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= README_MAX_LINES, f"README.md has {len(lines)} lines (at most {README_MAX_LINES})"


def test_readme_opens_with_make_demo_and_make_test() -> None:
    lines = README.read_text(encoding="utf-8").splitlines()
    assert lines[0].startswith("# "), "README.md starts with its title"
    rest = iter(lines[1:])
    first = next(line for line in rest if line.strip())
    block = [first]
    if _FENCE.match(first):  # a code block: up to its closing fence
        for line in rest:
            block.append(line)
            if _FENCE.match(line):
                break
    else:  # a paragraph: up to the next blank line
        for line in rest:
            if not line.strip():
                break
            block.append(line)
    opening = "\n".join(block)
    assert not first.startswith("#"), "the title is followed by the commands, not by another heading"
    assert "make demo" in opening and "make test" in opening, opening
