"""Compare two ``make demo`` output folders (``DEMO_DIR``) value by value, as printed.

    python -m studies.layout.compare_demo DIR_A DIR_B [--all]

Compared, each under a key naming its file (relative to the folder) and where in it:

- every number in every JSON results file (:data:`JSON_RESULTS`: each run's ``metrics.json``, the
  data summaries, the quality demo's ``scores/*.json``), by its printed text (``0.1`` and ``0.10000001``
  differ: the files are written with Python's shortest round-trip repr, so equal text is equal bits);
- every string in them whose key ends in ``hash`` (the caches' ``config_hash``/``manifest_hash``); other
  strings and booleans (paths, the git commit, ``git_dirty``) are not results and are left out;
- ``manifest_hash`` and ``config_hash`` of every cache's ``manifest.json``;
- every number printed in the text summaries (:data:`TEXT_RESULTS`: ``summary_<task>.txt``, the
  quality table), by line and position; words holding a ``/`` (paths) are skipped.

Wall-clock fields are left out: JSON keys matching :data:`TIMING_KEY` and printed numbers followed by a
time unit (``(completion: 412 s)``). A file present in one folder only is a difference.

Prints a table (every differing value; every value with ``--all``) and one line per file, then exits 0
when every value is equal, 1 when one differs, 2 on a bad folder or an unreadable file (one line).
"""
from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

# JSON files whose values are results (globs relative to the demo folder)
JSON_RESULTS = ("**/metrics.json", "**/data_summary.json", "quality/scores/*.json")
# manifests of the data caches (only their hashes are compared)
MANIFESTS = ("**/manifest.json",)
MANIFEST_KEYS = ("manifest_hash", "config_hash")
# text files whose printed numbers are results
TEXT_RESULTS = ("summary_*.txt", "quality/results.md", "quality/noise_strong_summary.txt")
# a key holding wall-clock time, not a result
TIMING_KEY = re.compile(r"(^|[/_.])(time|times|seconds|secs|duration|elapsed|wall|timestamp|date)([/_.]|$)|_s$|_sec$")
NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?|\bnan\b|\binf\b", re.IGNORECASE)
# a printed number followed by one of these words is a time
TIME_UNIT = re.compile(r"\s*(s|ms|min|h|sec|seconds|minutes)\b\)?")


class BadInput(Exception):
    """A folder or file that cannot be compared; the message names it."""


class Printed(str):
    """A JSON number kept as the text it was written as."""


def _read_json(path: Path):
    """The JSON value of ``path``, numbers as :class:`Printed`. A ``data_summary.json`` may carry text after its
    summary (lit3d-data before it kept its stdout for the JSON alone printed console lines there too): the
    summary is read and the rest skipped with a note on stderr, and so are log lines before it (``[YYYY-MM-DD
    ...`` lines, which older checkouts printed there); any other extra text is a bad file."""
    decoder = json.JSONDecoder(parse_float=Printed, parse_int=Printed, parse_constant=Printed)
    try:
        text = path.read_text("utf-8")
        if path.name == "data_summary.json":
            lines = text.splitlines(keepends=True)
            logged = 0
            while logged < len(lines) and LOG_LINE.match(lines[logged]):
                logged += 1
            if logged:
                print(f"compare_demo: note: {path}: {logged} log lines before the JSON summary skipped", file=sys.stderr)
                text = "".join(lines[logged:])
        try:
            return decoder.decode(text)
        except json.JSONDecodeError as exc:
            if path.name != "data_summary.json" or not exc.msg.startswith("Extra data"):
                raise
            value, end = decoder.raw_decode(text.lstrip())
            print(f"compare_demo: note: {path}: text after the JSON summary skipped ({len(text) - end} characters)",
                  file=sys.stderr)
            return value
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise BadInput(f"{path}: unreadable JSON ({exc})") from exc


LOG_LINE = re.compile(r"^\[\d{4}-\d\d-\d\d [\d:,]+\]")  # a logging line: [2026-11-29 05:06:01,350][name]...


def _leaves(value, prefix: str):
    """(dotted key, leaf) of every leaf of a JSON value."""
    if isinstance(value, dict):
        for k, v in value.items():
            yield from _leaves(v, f"{prefix}.{k}" if prefix else str(k))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from _leaves(v, f"{prefix}[{i}]")
    else:
        yield prefix, value


def json_values(path: Path) -> dict[str, str]:
    """Every number (as printed) and every ``*hash`` string of a JSON results file, timing keys left out."""
    out = {}
    for key, leaf in _leaves(_read_json(path), ""):
        if TIMING_KEY.search(key.lower()):
            continue
        if isinstance(leaf, Printed) or (isinstance(leaf, str) and key.lower().endswith("hash")):
            out[key] = str(leaf)
    return out


def manifest_values(path: Path) -> dict[str, str]:
    """The hashes of a cache's manifest (missing keys as ``-``)."""
    data = _read_json(path)
    if not isinstance(data, dict):
        raise BadInput(f"{path}: not a manifest (a JSON object expected)")
    return {k: str(data.get(k, "-")) for k in MANIFEST_KEYS}


def text_values(path: Path) -> dict[str, str]:
    """Every printed number of a text file by ``L<line>#<n> <word before>``; paths and times left out."""
    try:
        lines = path.read_text("utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise BadInput(f"{path}: unreadable text ({exc})") from exc
    out = {}
    for i, line in enumerate(lines, 1):
        n = 0
        words = line.split()
        for w, word in enumerate(words):
            if "/" in word and word.strip("()|,;:") != "/":
                continue
            for m in NUMBER.finditer(word):
                rest = word[m.end():] + " " + " ".join(words[w + 1:])
                if TIME_UNIT.match(rest) and not word[m.end():].strip(")").isalnum():
                    continue
                n += 1
                label = re.sub(r"\W+", "", words[w - 1])[:24] if w and "/" not in words[w - 1] else ""
                out[f"L{i}#{n} {label}".rstrip()] = m.group()
    return out


def _files(folder: Path, globs) -> list[Path]:
    return sorted({p for g in globs for p in folder.glob(g) if p.is_file()})


def collect(folder: str | Path) -> dict[str, dict[str, str]]:
    """{file relative to ``folder``: {key: printed value}} of every compared file of a demo folder."""
    folder = Path(folder)
    if not folder.is_dir():
        raise BadInput(f"{folder}: no such folder (a DEMO_DIR of make demo expected)")
    found: dict[str, dict[str, str]] = {}
    for p in _files(folder, MANIFESTS):
        found[p.relative_to(folder).as_posix()] = manifest_values(p)
    for p in _files(folder, JSON_RESULTS):
        found[p.relative_to(folder).as_posix()] = json_values(p)
    for p in _files(folder, TEXT_RESULTS):
        found[p.relative_to(folder).as_posix()] = text_values(p)
    if not found:
        raise BadInput(f"{folder}: no metrics.json, manifest.json or summary_*.txt (not a demo folder)")
    return found


def compare(a: dict[str, dict[str, str]], b: dict[str, dict[str, str]]):
    """Rows (file, key, value in a, value in b, same) of every value of either side; ``-`` when absent."""
    rows = []
    for f in sorted(a.keys() | b.keys()):
        va, vb = a.get(f), b.get(f)
        if va is None or vb is None:
            rows.append((f, "(file)", "present" if va is not None else "-", "present" if vb is not None else "-", False))
            continue
        for k in sorted(va.keys() | vb.keys()):
            x, y = va.get(k, "-"), vb.get(k, "-")
            rows.append((f, k, x, y, x == y))
    return rows


def table(rows, show_all: bool) -> str:
    """A markdown table of the rows (only the differing ones unless ``show_all``) and one line per file."""
    shown = [r for r in rows if show_all or not r[4]]
    out = []
    if shown:
        out += ["| file | value | A | B | same |", "|---|---|---|---|---|"]
        out += [f"| {f} | {k} | {x} | {y} | {'yes' if s else '**no**'} |" for f, k, x, y, s in shown]
        out.append("")
    per_file: dict[str, list[int]] = {}
    for f, _, _, _, s in rows:
        c = per_file.setdefault(f, [0, 0])
        c[0] += 1
        c[1] += not s
    out += [f"{f}: {n} values, {d} differ" for f, (n, d) in per_file.items()]
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], prog="python -m studies.layout.compare_demo")
    ap.add_argument("dir_a")
    ap.add_argument("dir_b")
    ap.add_argument("--all", action="store_true", help="list every compared value, not only the differing ones")
    args = ap.parse_args(argv)
    try:
        a, b = collect(args.dir_a), collect(args.dir_b)
    except BadInput as exc:
        print(f"compare_demo: {exc}", file=sys.stderr)
        return 2
    rows = compare(a, b)
    print(table(rows, args.all))
    differ = sum(not r[4] for r in rows)
    only_a = sum(not r[4] and r[3] == "-" for r in rows)
    only_b = sum(not r[4] and r[2] == "-" for r in rows)
    print(f"{'SAME' if not differ else 'DIFFERENT'}: {len(rows)} values compared, {differ} differ "
          f"({differ - only_a - only_b} changed, {only_a} only in A, {only_b} only in B; {args.dir_a} vs {args.dir_b})")
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
