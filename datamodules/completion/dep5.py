"""Per-file licences from a Debian machine-readable copyright file (DEP-5, ``usr/share/doc/<pkg>/copyright``).

A package that bundles many authors' files (UFO:AI's models) states each file's licence there, in
stanzas of ``Files:`` (paths or glob patterns, one or more per line, continued on indented lines),
``Copyright:`` and ``License:``. As the format says, the last stanza whose ``Files`` pattern matches a
path decides it; ``Files: *`` is the package's default. The ``Copyright`` lines of a stanza name its
group of authors, not the author of each file.
"""
from __future__ import annotations

import fnmatch
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class Stanza:
    """One ``Files`` stanza: its patterns, its copyright lines and the short name of its licence."""

    files: tuple[str, ...]
    copyright: tuple[str, ...]
    licence: str


def _fields(block: str) -> dict[str, list[str]]:
    """``{field: [value lines]}`` of one paragraph (continuation lines start with a space)."""
    out: dict[str, list[str]] = {}
    key = None
    for line in block.splitlines():
        if line[:1] in (" ", "\t") and key is not None:
            text = line.strip()
            if text and text != ".":
                out[key].append(text)
        elif ":" in line:
            key, _, value = line.partition(":")
            out[key.strip()] = [value.strip()] if value.strip() else []
    return out


def parse_dep5(text: str) -> list[Stanza]:
    """The ``Files`` stanzas of a DEP-5 copyright text, in file order (stand-alone licence texts skipped)."""
    stanzas = []
    for block in text.replace("\r\n", "\n").split("\n\n"):
        f = _fields(block)
        if "Files" not in f:
            continue
        patterns = tuple(p for line in f["Files"] for p in line.split())
        licence = (f.get("License") or [""])[0]
        stanzas.append(Stanza(patterns, tuple(f.get("Copyright", [])), licence))
    return stanzas


def stanza_of(stanzas: list[Stanza], path: str) -> Stanza | None:
    """The stanza that decides ``path`` (relative to the package's source root): the last one that matches."""
    hit = None
    for s in stanzas:
        if any(p == path or fnmatch.fnmatchcase(path, p) for p in s.files):
            hit = s
    return hit


def read_dep5(path: Path) -> list[Stanza]:
    """:func:`parse_dep5` of a file; ``[]`` when it is missing or not DEP-5 (the caller keeps its fallback)."""
    try:
        text = Path(path).read_text(encoding="utf-8", errors="replace")
    except OSError:
        return []
    return parse_dep5(text) if text.startswith("Format:") else []
