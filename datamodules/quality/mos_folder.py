"""Reader for a human-rated set of your own (``data=mos_folder``): shape folders plus one score table.

Layout read::

    DIR/
      scores.csv                  one row per rated stimulus (any one .csv/.xlsx/.xls under DIR,
                                  or data.spreadsheet=PATH)
      <shape>/<shape>.<ext>       the reference of <shape>
      <shape>/<stimulus>.<ext>    a rated stimulus of <shape>

``ext``: a mesh (``.obj .ply .off .stl .glb .gltf``) or a point cloud (``.ply`` without faces,
``.xyz .pts .txt``, a ``.zip`` holding one ``.ply``); two point clouds are compared as points, as in
``data=cpcd2``. Columns of the table (header names: case, spaces and underscores ignored):

=============  ===========================================================================
``stimulus``   the stimulus file's name, with or without extension (also ``name``, ``file``,
               ``model``, ``mesh``, ``distorted``)
``shape``      optional: the shape it belongs to (else the folder the file is in)
``mos``        its score (also ``score``, ``dmos``, ``mean opinion score``)
``reference``  optional: the reference file of the row's shape, relative to DIR or to
               DIR/<shape>/ (else DIR/<shape>/<shape>.<ext>)
=============  ===========================================================================

The shapes are the folders (or the ``shape`` column), never a fixed list. The score's range and
direction are settings: ``score_range`` (None = the lowest and highest score of the table) and
``higher_is_better`` (required: MOS is usually higher = better, DMOS higher = worse).
Problems are one :class:`~datamodules.quality.mos.MosDataError` naming the file (and row) and what
is wrong; ``on_error="skip"`` turns bad rows into warnings listed in ``skipped``.
"""
from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path

from datamodules.quality.mos import (SHEET_EXTS, MosDataError, MosDataset, MosItem, MosLayout, read_sheet_rows,
                                     row_problem)

STIMULUS_EXTS = (".obj", ".ply", ".off", ".stl", ".glb", ".gltf", ".xyz", ".pts", ".txt", ".zip")
COLUMNS = {
    "stimulus": ("stimulus", "name", "file", "filename", "model", "mesh", "distorted", "distortedmodel"),
    "score": ("mos", "score", "dmos", "meanopinionscore"),
    "shape": ("shape",),
    "reference": ("reference", "referencefile", "ref"),
}


def _key(text: object) -> str:
    """'Cow_Noise-0.5.OBJ' -> 'cownoise05.obj' without the extension: letters and digits, lower case."""
    s = str(text).strip()
    for ext in STIMULUS_EXTS:
        if s.lower().endswith(ext):
            s = s[: -len(ext)]
            break
    return re.sub(r"[^a-z0-9]", "", s.lower())


def _table(path: Path, sheet: str | int | None) -> list[dict]:
    """Rows ``{"row", "stimulus", "score", "shape", "reference"}`` (missing cells: "") of the first sheet."""
    rows = next(iter(read_sheet_rows(path, sheet).values()), [])
    if not rows:
        raise MosDataError(f"{path}: empty score table")
    head = [_key(h) if h is not None else "" for h in rows[0]]
    col = {}
    for want, names in COLUMNS.items():
        hit = [i for i, h in enumerate(head) if h in names and i not in col.values()]
        if hit:
            col[want] = hit[0]
    missing = [c for c in ("stimulus", "score") if c not in col]
    if missing:
        raise MosDataError(f"{path}: no {' or '.join(missing)} column in the header "
                           f"({', '.join(str(h) for h in rows[0])}); expected stimulus, shape (optional), mos, "
                           "reference (optional)")
    out = []
    for r, cells in enumerate(rows[1:], start=2):
        if all(c in (None, "") or not str(c).strip() for c in cells):
            continue
        cell = lambda c: str(cells[col[c]]).strip() if c in col and col[c] < len(cells) and cells[col[c]] is not None else ""  # noqa: E731
        out.append({"row": r, **{c: cell(c) for c in COLUMNS}})
    if not out:
        raise MosDataError(f"{path}: the score table has a header but no rows")
    return out


def _score_table(root: Path, spreadsheet: str | Path | None) -> Path:
    if spreadsheet is not None:
        p = Path(spreadsheet).expanduser()
        p = p if p.is_absolute() else root / p
        if not p.is_file():
            raise MosDataError(f"{p}: score table not found (data.spreadsheet)")
        return p
    found = sorted(p for p in root.glob("*") if p.is_file() and p.suffix.lower() in SHEET_EXTS
                   and not p.name.startswith(("~$", ".")))
    if len(found) != 1:
        what = "no score table" if not found else f"{len(found)} score tables ({', '.join(p.name for p in found)})"
        raise MosDataError(f"{root}: {what} ({', '.join(SHEET_EXTS)}) directly in the folder; "
                           "set data.spreadsheet=PATH")
    return found[0]


def index_stimuli(root: Path) -> dict[str, dict[str, list[Path]]]:
    """``{shape folder: {name key: [files]}}`` of the files in ``root/<shape>/`` (one level)."""
    out: dict[str, dict[str, list[Path]]] = {}
    for folder in sorted(p for p in root.iterdir() if p.is_dir() and not p.name.startswith(".")):
        files = out.setdefault(folder.name, {})
        for f in sorted(folder.iterdir()):
            if f.is_file() and f.suffix.lower() in STIMULUS_EXTS and not f.name.startswith("."):
                files.setdefault(_key(f.name), []).append(f)
    return out


def _shape_folder(shape: str, folders: Sequence[str]) -> str | None:
    return next((f for f in folders if f == shape), None) or next((f for f in folders if _key(f) == _key(shape)), None)


def _reference(root: Path, shape: str, folder: str | None, given: str, files: dict[str, list[Path]]) -> Path | None:
    if given:
        for base in ((root / folder) if folder else root, root):
            if (base / given).is_file():
                return base / given
        hits = files.get(_key(given), [])
        return hits[0] if hits else None
    hits = files.get(_key(shape), [])
    return hits[0] if hits else None


def read_mos_folder(root: str | Path, spreadsheet: str | Path | None = None, sheet: str | int | None = None,
                    score_range: Sequence[float | None] | None = None, higher_is_better: bool | None = None,
                    on_error: str = "raise", name: str = "mos_folder", **_ignored) -> MosDataset:
    """Read DIR (layout in the module docstring) into rated (reference, stimulus, score) items.

    Args:
        root: DIR. spreadsheet / sheet: the score table (default: the one table in DIR) and its sheet.
        score_range: ``(lo, hi)`` of the scale (None or a None bound: the table's lowest / highest score).
        higher_is_better: the score's direction (required). on_error: ``"raise"`` or ``"skip"``.
        name: the dataset's name in items and reports.
    """
    root = Path(root).expanduser()
    if not root.is_dir():
        raise MosDataError(f"{root}: folder not found (set data.root=DIR: DIR/<shape>/<stimulus> files + one score table)")
    if higher_is_better is None:
        raise MosDataError(f"{root}: the score's direction is not set: data.higher_is_better=true (MOS) or false (DMOS)")
    lo, hi = tuple(score_range) if score_range else (None, None)
    table = _score_table(root, spreadsheet)
    rows = _table(table, sheet)
    stimuli = index_stimuli(root)
    if not any(stimuli.values()):
        raise MosDataError(f"{root}: no shape folder holds a mesh or point cloud ({' '.join(STIMULUS_EXTS)}); "
                           "expected DIR/<shape>/<stimulus> files")
    items, skipped, refs, used = [], [], {}, set()

    bad = row_problem(on_error, skipped)

    for row in rows:
        where = f"{table} row {row['row']} ('{row['stimulus']}')"
        if not row["stimulus"]:
            bad(f"{table} row {row['row']}: empty stimulus name")
            continue
        k = _key(row["stimulus"])
        folder = _shape_folder(row["shape"], list(stimuli)) if row["shape"] else None
        if row["shape"] and folder is None and not row["reference"]:
            bad(f"{where}: shape '{row['shape']}' has no folder {root / row['shape']}")
            continue
        hits = [(f, p) for f, files in stimuli.items() if folder in (None, f) for p in files.get(k, [])]
        if not hits:
            where_looked = root / folder if folder else f"{root}/<shape>/"
            bad(f"{where}: no file named '{row['stimulus']}' in {where_looked} ({' '.join(STIMULUS_EXTS)})")
            continue
        if len(hits) > 1:
            bad(f"{where}: '{row['stimulus']}' names {len(hits)} files ({', '.join(str(p) for _, p in hits)}); "
                "add a shape column or rename one")
            continue
        folder, path = hits[0]
        shape = row["shape"] or folder
        try:
            score = float(row["score"].replace(",", "."))
        except ValueError:
            bad(f"{where}: score {row['score']!r} is not a number")
            continue
        if score != score or (lo is not None and score < lo) or (hi is not None and score > hi):
            bad(f"{where}: score {score} outside data.score_range {lo}..{hi}")
            continue
        if shape not in refs or row["reference"]:
            ref = _reference(root, shape, folder, row["reference"], stimuli.get(folder, {}))
            if ref is None:
                expected = row["reference"] or f"{shape}/{shape}.<ext>"
                raise MosDataError(f"{where}: no reference for shape '{shape}' (looked for {root / expected}); "
                                   "add it or name it in a reference column")
            if shape in refs and refs[shape] != ref:
                raise MosDataError(f"{where}: shape '{shape}' has two references ({refs[shape].name}, {ref.name})")
            refs[shape] = ref
        if path == refs[shape]:
            bad(f"{where}: names the reference of '{shape}' itself; references are not rated")
            continue
        used.add(path)
        items.append(MosItem(name, shape, path.stem, refs[shape], path, score))
    if not items:
        raise MosDataError(f"{table}: no usable rows ({len(skipped)} skipped)")
    known = used | set(refs.values())
    unrated = sorted(p for files in stimuli.values() for ps in files.values() for p in ps if p not in known)
    layout = MosLayout(name, tuple(refs), (lo, hi), bool(higher_is_better))
    return MosDataset(layout, items, table, unrated, skipped)
