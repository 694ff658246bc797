"""Commands in the docs that name ``../shared`` (the developers' data folder beside the checkout, which
a user's clone does not have) are marked as "if you have the data" examples.

The convention (find them all with ``grep -rin "if you have" README.md docs``):

- a line of a code block (fenced or indented) that names ``../shared`` is marked when the line itself
  carries a comment ``# if you have ...``, or when the paragraph right before the code block (the
  non-blank lines above it, up to the blank line before them) says "if you have";
- an inline backticked command that names it (a span with a space in it: ``lit3d-train ...
  data.root=../shared/data/x``) is marked when its paragraph (or list item, or table cell) says
  "if you have";
- a backticked path alone (``../shared/data/recgan_sample``) names where the developers' data lies:
  a mention, not a command, so it needs no mark.

"if you have" is matched in any case. Markdown is parsed with markdown-it-py (CommonMark), so code
blocks inside list items count as code blocks.
"""
from __future__ import annotations


import pytest
from markdown_it import MarkdownIt
from tests.helpers.paths import REPO as ROOT

SHARED = "../shared"
MARK = "if you have"
DOCS = sorted(["README.md", *(p.relative_to(ROOT).as_posix() for p in (ROOT / "docs").rglob("*.md"))])


def _paragraph_before(lines: list[str], start: int) -> str:
    """The non-blank lines right above line ``start`` (0-based), up to the blank line before them."""
    i = start - 1
    while i >= 0 and not lines[i].strip():
        i -= 1
    end = i + 1
    while i >= 0 and lines[i].strip():
        i -= 1
    return "\n".join(lines[i + 1:end])


def unmarked_commands(text: str) -> list[tuple[int, str]]:
    """``(line number, text)`` of every command in the markdown ``text`` that names ``../shared``
    without an "if you have" mark (module doc)."""
    lines = text.splitlines()
    found = []
    for token in MarkdownIt("commonmark").parse(text):
        if token.type in ("fence", "code_block") and SHARED in token.content:
            start = token.map[0]
            block_marked = MARK in _paragraph_before(lines, start).lower()
            first = start + (1 if token.type == "fence" else 0)  # a fence's content starts below its ``` line
            for k, line in enumerate(token.content.splitlines()):
                if SHARED in line and not block_marked and f"# {MARK}" not in line.lower():
                    found.append((first + k + 1, line.strip()))
        elif token.type == "inline" and SHARED in token.content and MARK not in token.content.lower():
            line = token.map[0] + 1
            for child in token.children or []:
                line += child.type in ("softbreak", "hardbreak")  # the line a span starts on
                if child.type == "code_inline" and SHARED in child.content and " " in child.content.strip():
                    found.append((line, child.content))
    return found


@pytest.mark.parametrize("doc", DOCS)
def test_commands_naming_the_shared_data_are_marked(doc):
    bad = unmarked_commands((ROOT / doc).read_text(encoding="utf-8"))
    assert not bad, (f"{doc}: commands that name {SHARED} (not in a clone) without an '{MARK} ...' note before "
                     f"them or '# {MARK} ...' on the line: " + "; ".join(f"line {n}: {c}" for n, c in bad))


def test_the_scan_sees_every_kind_of_command():
    """Fenced, indented and list-nested code blocks and inline commands are seen; marks before a block,
    on a line or in an inline command's paragraph clear them; a path alone is a mention."""
    doc = "\n".join([
        "Run this:",  # 1
        "",
        "```bash",
        "lit3d-train data.root=../shared/data/a",  # 4: unmarked
        "lit3d-eval data.root=../shared/data/a   # If you have the data",  # 5: its own mark
        "```",
        "",
        "The study:",  # 8
        "",
        "    python -m x --root ../shared/data/b",  # 10: indented, unmarked
        "",
        "If you have the data (`../shared/data/b`), then:",  # 12: a mention, and a mark
        "",
        "    python -m x --root ../shared/data/b",  # 14: marked by the paragraph before
        "",
        "- an item, run with `lit3d-train data.root=../shared/data/c` here",  # 16: inline, unmarked
        "- an item:",  # 17
        "",
        "      python -m y ../shared/data/d",  # 19: a code block in a list item, unmarked
        "",
        "- if you have it: `lit3d-train data.root=../shared/data/c`",  # 21: marked inline
        "- a path alone: `../shared/data/e`",  # 22: a mention
    ]) + "\n"
    assert [n for n, _ in unmarked_commands(doc)] == [4, 10, 16, 19]
    assert unmarked_commands(doc)[0] == (4, "lit3d-train data.root=../shared/data/a")
