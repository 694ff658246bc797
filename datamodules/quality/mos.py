"""Readers for human-rated mesh quality datasets: meshes + a spreadsheet of opinion scores.

The three datasets of thesis ch. 4 ship as a folder of meshes plus an Excel file.
None is available here, so the readers follow the documented layout and are tested
on files the tests write in it:

=====================  =====================================================  ==========  ===============
dataset                shapes                                                 score       direction
=====================  =====================================================  ==========  ===============
LIRIS/EPFL General     armadillo, dyno, rockerarm, venus (22 models each)     MOS 0..10   higher = worse
LIRIS Masking          armadillo, dyno, lion, bimba (reference + 6 each)      MOS 0..4    higher = better
Guo et al. 2016        dwarf, hulk, squirrel, statue (21 distortions each)    MOS         higher = better
=====================  =====================================================  ==========  ===============

Layout read (all three)::

    ROOT/
      <anything>.xlsx | .xls | .csv       the scores: one row per distorted model
      <shape>/<shape>.obj                 the reference (file stem == shape name, or a
      <shape>/<distorted model>.obj         stem containing "ref"/"original"); .ply/.off too
      (or all meshes flat in ROOT or ROOT/<subfolder>/, shape taken from the row)

Spreadsheet: the first sheet (or ``sheet=``) with a header row (searched in the first
20 rows, so title lines above it are fine) that has a model-name column and a score
column. Recognised headers (case, spaces, dots and underscores ignored):
name: ``distorted model``, ``distorted``, ``stimulus``, ``model``, ``mesh``, ``file(name)``, ``name``, ``object``;
score: ``mos``, ``mos normalized``, ``score``, ``mean opinion score``, ``dmos``;
shape (optional): ``shape``, ``reference``, ``ref``, ``original``, ``source``, ``object`` (when not the name).
Other columns (per-observer scores, metric values) are ignored. A row's model name is
matched to a mesh file by stem, case-insensitively, with or without extension.

Problems are one :class:`MosDataError` naming the file (and row) and what is wrong:
missing spreadsheet, missing column, a row whose mesh is not there, a row that
matches no known shape, a shape without reference, a score out of the published
range or not a number. ``on_error="skip"`` skips bad rows with a warning instead.
Mesh files no row mentions (besides references) are reported in ``unrated``.
"""
from __future__ import annotations

import csv
import re
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from datamodules.cache import DataError

MESH_EXTS = (".obj", ".ply", ".off", ".stl")
SHEET_EXTS = (".xlsx", ".xlsm", ".xls", ".csv")
# most specific first: a sheet with "Object" and "Distorted model" names the pair by the latter
NAME_HEADERS = ("distortedmodel", "distorted", "stimulus", "model", "modelname", "mesh", "filename", "file", "name",
                "objectname", "object")
SCORE_HEADERS = ("mos", "mosnormalized", "normalizedmos", "score", "meanopinionscore", "dmos", "mosafternormalization")
SHAPE_HEADERS = ("shape", "reference", "ref", "original", "source", "referencemodel", "referencename", "object")
REF_HINTS = ("ref", "original", "orig")


class MosDataError(DataError):
    """A dataset file is missing or malformed (the message names the file and the problem)."""


@dataclass(frozen=True)
class MosItem:
    """One rated pair: the distorted mesh, its shape's reference, and the published score."""

    dataset: str
    shape: str
    name: str
    reference: Path
    distorted: Path
    score: float


@dataclass(frozen=True)
class MosLayout:
    """What a dataset's files look like and how its score reads."""

    name: str
    shapes: tuple[str, ...]
    score_range: tuple[float | None, float | None]
    higher_is_better: bool
    target_name: str = "MOS"


LAYOUTS = {
    "liris_epfl": MosLayout("liris_epfl", ("armadillo", "dyno", "rockerarm", "venus"), (0.0, 10.0), False),
    "liris_masking": MosLayout("liris_masking", ("armadillo", "dyno", "lion", "bimba"), (0.0, 4.0), True),
    "guo2016": MosLayout("guo2016", ("dwarf", "hulk", "squirrel", "statue"), (None, None), True),
}


@dataclass
class MosDataset:
    """Items of one dataset plus what the reader noticed."""

    layout: MosLayout
    items: list[MosItem]
    spreadsheet: Path
    unrated: list[Path] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)

    @property
    def shapes(self) -> list[str]:
        return list(dict.fromkeys(i.shape for i in self.items))

    def score_range(self) -> tuple[float, float]:
        lo, hi = self.layout.score_range
        scores = [i.score for i in self.items]
        return (min(scores) if lo is None else lo, max(scores) if hi is None else hi)


def row_problem(on_error: str, skipped: list[str]):
    """``bad(msg)`` of a reader: raise :class:`MosDataError` (``on_error="raise"``), or warn, append ``msg`` to
    ``skipped`` and go on (``"skip"``)."""
    def bad(msg: str) -> None:
        if on_error == "raise":
            raise MosDataError(msg)
        warnings.warn(msg + " (skipped)", stacklevel=3)
        skipped.append(msg)

    return bad


def norm_key(text: object) -> str:
    """Lower-case, drop a mesh extension and anything but letters/digits: 'Armadillo_Noise-0.5.OBJ' -> 'armadillonoise05'."""
    s = str(text).strip()
    low = s.lower()
    for ext in MESH_EXTS:
        if low.endswith(ext):
            s = s[: -len(ext)]
            break
    return re.sub(r"[^a-z0-9]", "", s.lower())


def _header_key(text: object) -> str:
    return re.sub(r"[^a-z0-9]", "", str(text or "").lower())


# --------------------------------------------------------------------------- spreadsheets
def read_sheet_rows(path: Path, sheet: str | int | None = None) -> dict[str, list[list[object]]]:
    """Sheet name -> rows (lists of cell values) for .xlsx/.xlsm (openpyxl), .xls (xlrd), .csv."""
    ext = path.suffix.lower()
    try:
        if ext in (".xlsx", ".xlsm"):
            import openpyxl

            wb = openpyxl.load_workbook(path, read_only=True, data_only=True)
            try:
                names = wb.sheetnames if sheet is None else [wb.sheetnames[sheet] if isinstance(sheet, int) else sheet]
                return {n: [list(r) for r in wb[n].iter_rows(values_only=True)] for n in names}
            finally:
                wb.close()
        if ext == ".xls":
            try:
                import xlrd
            except ImportError as exc:  # pragma: no cover - depends on the install
                raise MosDataError(f"{path}: reading .xls needs the 'xlrd' package (pip install xlrd), "
                                   "or save the sheet as .xlsx") from exc
            book = xlrd.open_workbook(str(path))
            names = book.sheet_names() if sheet is None else [book.sheet_names()[sheet] if isinstance(sheet, int) else sheet]
            return {n: [book.sheet_by_name(n).row_values(i) for i in range(book.sheet_by_name(n).nrows)] for n in names}
        if ext == ".csv":
            with open(path, newline="", encoding="utf-8-sig") as f:
                return {path.stem: [list(r) for r in csv.reader(f)]}
    except MosDataError:
        raise
    except KeyError as exc:
        raise MosDataError(f"{path}: no sheet {sheet!r}") from exc
    except Exception as exc:
        raise MosDataError(f"{path}: not a readable spreadsheet ({type(exc).__name__}: {exc})") from exc
    raise MosDataError(f"{path}: unsupported spreadsheet type '{ext}' (use {', '.join(SHEET_EXTS)})")


def _find_header(rows: list[list[object]]) -> tuple[int, dict[str, int]] | None:
    for r, row in enumerate(rows[:20]):
        keys = [_header_key(c) for c in row]
        cols: dict[str, int] = {}
        for kind, aliases in (("name", NAME_HEADERS), ("score", SCORE_HEADERS), ("shape", SHAPE_HEADERS)):
            for alias in aliases:  # alias order = preference
                if alias in keys and keys.index(alias) not in cols.values():
                    cols[kind] = keys.index(alias)
                    break
        if "name" in cols and "score" in cols:
            return r, cols
    return None


def read_score_table(path: Path, sheet: str | int | None = None) -> list[dict]:
    """Rows of the score spreadsheet: ``{"row": excel row number, "name", "score" (raw), "shape" or None}``."""
    sheets = read_sheet_rows(path, sheet)
    seen_headers = []
    for sheet_name, rows in sheets.items():
        found = _find_header(rows)
        if found is None:
            seen_headers.append(f"'{sheet_name}': {[c for c in (rows[0] if rows else []) if c not in (None, '')]}")
            continue
        r0, cols = found
        out = []
        for r, row in enumerate(rows[r0 + 1:], start=r0 + 2):
            cell = lambda k: row[cols[k]] if k in cols and cols[k] < len(row) else None  # noqa: E731
            name = cell("name")
            if name is None or str(name).strip() == "":
                if all(c in (None, "") for c in row):
                    continue  # blank line
                raise MosDataError(f"{path} sheet '{sheet_name}' row {r}: empty model name")
            out.append({"row": r, "sheet": sheet_name, "name": str(name).strip(), "score": cell("score"),
                        "shape": (str(cell("shape")).strip() or None) if cell("shape") not in (None, "") else None})
        return out
    raise MosDataError(
        f"{path}: no sheet has both a model-name column ({', '.join(NAME_HEADERS[:4])}, ...) and a score column "
        f"({', '.join(SCORE_HEADERS[:3])}, ...); first rows seen: {'; '.join(seen_headers)}")


# --------------------------------------------------------------------------- meshes
def index_meshes(root: Path) -> dict[str, list[Path]]:
    """normalised stem -> mesh paths under ``root`` (recursive)."""
    index: dict[str, list[Path]] = {}
    for p in sorted(root.rglob("*")):
        if p.is_file() and p.suffix.lower() in MESH_EXTS:
            index.setdefault(norm_key(p.name), []).append(p)
    return index


def _is_reference_name(stem_key: str, shape_key: str) -> bool:
    if stem_key == shape_key:
        return True
    rest = stem_key.replace(shape_key, "", 1) if stem_key.startswith(shape_key) else None
    return rest is not None and rest in REF_HINTS + ("reference", "originalmodel")


def find_reference(root: Path, shape: str, meshes: dict[str, list[Path]]) -> Path | None:
    """The reference mesh of ``shape``: stem == shape (preferred in ROOT/<shape>/) or shape + ref/original."""
    skey = norm_key(shape)
    hits = [p for k, ps in meshes.items() if _is_reference_name(k, skey) for p in ps]
    if not hits:
        return None
    hits.sort(key=lambda p: (norm_key(p.name) != skey, norm_key(p.parent.name) != skey, len(p.parts), str(p)))
    return hits[0]


def _shape_of(row: dict, mesh: Path, shapes: Sequence[str], root: Path) -> str | None:
    """Row's shape column, else the mesh's folder name, else the shape whose name prefixes the model name."""
    keys = {norm_key(s): s for s in shapes}
    if row.get("shape"):
        k = norm_key(row["shape"])
        for sk, s in keys.items():
            if k == sk or k.startswith(sk):
                return s
        return None
    for parent in mesh.relative_to(root).parents:
        if norm_key(parent.name) in keys:
            return keys[norm_key(parent.name)]
    nk = norm_key(row["name"])
    best = [s for sk, s in keys.items() if nk.startswith(sk)]
    return max(best, key=len) if best else None


def _spreadsheet(root: Path, spreadsheet: str | Path | None) -> Path:
    if spreadsheet is not None:
        p = Path(spreadsheet)
        p = p if p.is_absolute() else root / p
        if not p.is_file():
            raise MosDataError(f"{p}: score spreadsheet not found")
        return p
    found = sorted(p for p in root.rglob("*") if p.suffix.lower() in SHEET_EXTS and not p.name.startswith(("~$", ".")))
    if not found:
        raise MosDataError(f"{root}: no score spreadsheet ({', '.join(SHEET_EXTS)}) found; set spreadsheet=PATH")
    # prefer a file that says MOS / subjective in its name
    found.sort(key=lambda p: (not re.search(r"mos|subj|score|opinion", p.name, re.I), len(p.parts), str(p)))
    return found[0]


def read_mos_dataset(root: str | Path, layout: MosLayout | str, spreadsheet: str | Path | None = None,
                     sheet: str | int | None = None, shapes: Sequence[str] | None = None,
                     score_range: tuple[float | None, float | None] | None = None,
                     on_error: str = "raise") -> MosDataset:
    """Read ROOT (layout in the module docstring) into rated (reference, distorted, score) items.

    shapes / score_range override the layout's (e.g. a subset, or a rescaled sheet).
    on_error: "raise" (default) or "skip" (bad rows become warnings, listed in ``skipped``).
    """
    if isinstance(layout, str):
        if layout not in LAYOUTS:
            raise KeyError(f"unknown dataset layout '{layout}' (known: {', '.join(LAYOUTS)})")
        layout = LAYOUTS[layout]
    if shapes is not None or score_range is not None:
        layout = MosLayout(layout.name, tuple(shapes or layout.shapes), tuple(score_range or layout.score_range),
                           layout.higher_is_better, layout.target_name)
    if on_error not in ("raise", "skip"):
        raise ValueError(f"on_error must be 'raise' or 'skip', got {on_error!r}")
    root = Path(root).expanduser()
    if not root.is_dir():
        raise MosDataError(f"{root}: dataset root not found (set data.root=PATH to the unpacked {layout.name} folder)")
    sheet_path = _spreadsheet(root, spreadsheet)
    rows = read_score_table(sheet_path, sheet)
    if not rows:
        raise MosDataError(f"{sheet_path}: the score table has a header but no rows")
    meshes = index_meshes(root)
    if not meshes:
        raise MosDataError(f"{root}: no mesh files ({', '.join(MESH_EXTS)}) found")
    refs: dict[str, Path] = {}
    items: list[MosItem] = []
    skipped: list[str] = []
    lo, hi = layout.score_range

    bad = row_problem(on_error, skipped)

    used: set[Path] = set()
    for row in rows:
        where = f"{sheet_path} sheet '{row['sheet']}' row {row['row']} ('{row['name']}')"
        paths = meshes.get(norm_key(row["name"]))
        if not paths:
            bad(f"{where}: no mesh file named '{row['name']}' under {root} (looked for {', '.join(MESH_EXTS)})")
            continue
        mesh = paths[0]
        shape = _shape_of(row, mesh, layout.shapes, root)
        if shape is None:
            named = row.get("shape") or (mesh.parent.name if mesh.parent != root else None)
            bad(f"{where}: matches no shape of {layout.name} ({', '.join(layout.shapes)})"
                + (f"; '{named}' is not one of its published shapes: for a rated set of your own use data=mos_folder"
                   if named else "; add a shape column or put the mesh in a folder named after its shape"))
            continue
        raw = row["score"]
        try:
            score = float(str(raw).replace(",", ".")) if not isinstance(raw, (int, float)) else float(raw)
        except (TypeError, ValueError):
            bad(f"{where}: score {raw!r} is not a number")
            continue
        if score != score or (lo is not None and score < lo) or (hi is not None and score > hi):
            bad(f"{where}: score {score} outside the published range {lo}..{hi} of {layout.name}")
            continue
        if shape not in refs:
            ref = find_reference(root, shape, meshes)
            if ref is None:
                raise MosDataError(f"{root}: no reference mesh for shape '{shape}' (expected {shape}/{shape}.obj "
                                   f"or a file named like '{shape}_ref.obj')")
            refs[shape] = ref
        if mesh == refs[shape]:
            bad(f"{where}: names the reference mesh itself ({mesh.name}); references are not rated pairs")
            continue
        used.add(mesh)
        items.append(MosItem(layout.name, shape, row["name"], refs[shape], mesh, score))
    if not items:
        raise MosDataError(f"{sheet_path}: no usable rows ({len(skipped)} skipped)")
    known = used | set(refs.values())
    unrated = sorted(p for ps in meshes.values() for p in ps
                     if p not in known and _shape_key_in(p, root, layout.shapes))
    return MosDataset(layout, items, sheet_path, unrated, skipped)


def _shape_key_in(path: Path, root: Path, shapes: Sequence[str]) -> bool:
    keys = {norm_key(s) for s in shapes}
    parts = [norm_key(p.name) for p in path.relative_to(root).parents] + [norm_key(path.name)]
    return any(any(k.startswith(s) for s in keys) for k in parts if k)


def read_liris_epfl(root, **kw) -> MosDataset:
    """LIRIS/EPFL General-Purpose (Lavoué et al. 2006): MOS 0 (no distortion) .. 10 (extreme)."""
    return read_mos_dataset(root, "liris_epfl", **kw)


def read_liris_masking(root, **kw) -> MosDataset:
    """LIRIS Masking (Lavoué 2009): MOS 4 (identical) .. 0 (most degraded)."""
    return read_mos_dataset(root, "liris_masking", **kw)


def read_guo2016(root, **kw) -> MosDataset:
    """Guo et al. 2016: noise + Taubin smoothing on dwarf/hulk/squirrel/statue (higher MOS = better)."""
    return read_mos_dataset(root, "guo2016", **kw)


READERS = {"liris_epfl": read_liris_epfl, "liris_masking": read_liris_masking, "guo2016": read_guo2016}
