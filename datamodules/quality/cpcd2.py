"""Reader for coloured point-cloud quality data in the CPCD2.0 layout (zipped ASCII PLY + MOS table).

Layout read::

    ROOT/
      mos.csv                      stimulus, codec, mos, file   (one row per distorted cloud)
      Original/<cloud>.zip         the reference (one .ply inside; or <cloud>.ply)
      Database_10/<stimulus>.zip   distorted clouds (any folder: the row's ``file`` column,
                                   relative to ROOT, or found by stimulus name)

A stimulus is named ``<cloud>_<code>`` (``phil_G_01``); its reference is
``Original/<cloud>.zip``. MOS is on 1..5, higher = better. A row whose ``file`` cell is
empty and whose stimulus has no file under ROOT is a stimulus of the study that this copy
does not hold: it is left out and listed in ``skipped`` (no warning). Everything else that
is wrong is one :class:`datamodules.quality.mos.MosDataError` naming the file and row
(``on_error="skip"`` turns bad rows into warnings). The clouds themselves are read when
the features are computed (:func:`lit3d.render.point_clouds.load_points`).
"""
from __future__ import annotations

import csv
import re
from pathlib import Path

from datamodules.quality.mos import MosDataError, MosDataset, MosItem, MosLayout, row_problem

CLOUD_EXTS = (".zip", ".ply")
SCORE_RANGE = (1.0, 5.0)


def _key(text: str) -> str:
    return re.sub(r"[^a-z0-9]", "", str(text).lower())


def _table(path: Path) -> list[dict]:
    """Rows of ``mos.csv`` as ``{"stimulus", "mos", "file", "row"}`` (header names normalised)."""
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:
            rows = list(csv.reader(f))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise MosDataError(f"{path}: unreadable score table ({type(exc).__name__}: {exc})") from exc
    if not rows:
        raise MosDataError(f"{path}: empty score table")
    head = [_key(h) for h in rows[0]]
    col = {}
    for want, names in (("stimulus", ("stimulus", "name", "stimuli")), ("mos", ("mos", "score")), ("file", ("file",))):
        hit = [i for i, h in enumerate(head) if h in names]
        if hit:
            col[want] = hit[0]
    missing = [c for c in ("stimulus", "mos") if c not in col]
    if missing:
        raise MosDataError(f"{path}: no {' or '.join(missing)} column in the header ({', '.join(rows[0])})")
    out = []
    for r, cells in enumerate(rows[1:], start=2):
        if not any(c.strip() for c in cells):
            continue

        def cell(c):
            return cells[col[c]].strip() if c in col and col[c] < len(cells) else ""

        out.append({"stimulus": cell("stimulus"), "mos": cell("mos"), "file": cell("file"), "row": r})
    return out


def stimulus_family(stimulus: str) -> str:
    """Distortion family of a CPCD2 stimulus name: ``phil_G_01`` -> ``G`` (``<cloud>_<family>_<n>``; a name
    of two parts gives the first letter of the second: ``phil_N35`` -> ``N``)."""
    parts = stimulus.split("_")
    return parts[1] if len(parts) > 2 else parts[-1][:1]


def _find(root: Path, stem: str, folder: str | None = None) -> Path | None:
    base = root / folder if folder else root
    if not base.is_dir():
        return None
    for ext in CLOUD_EXTS:
        hits = sorted(base.rglob(f"{stem}{ext}"))
        if hits:
            return hits[0]
    return None


def read_cpcd2(root: str | Path, spreadsheet: str | Path | None = None, on_error: str = "raise",
               **_ignored) -> MosDataset:
    """Read ROOT (layout in the module doc) into rated (reference, distorted, MOS) items.

    Args:
        root: the dataset folder.
        spreadsheet: the score table (default ``ROOT/mos.csv``).
        on_error: ``"raise"`` or ``"skip"`` (bad rows become warnings listed in ``skipped``).
    """
    root = Path(root).expanduser()
    if not root.is_dir():
        raise MosDataError(f"{root}: dataset root not found (set data.root=PATH to the CPCD2-style folder)")
    sheet = Path(spreadsheet) if spreadsheet else root / "mos.csv"
    if not sheet.is_file():
        raise MosDataError(f"{sheet}: score table not found (expected mos.csv with stimulus, mos, file columns)")
    rows = _table(sheet)
    items, skipped, refs = [], [], {}

    bad = row_problem(on_error, skipped)

    for row in rows:
        name, where = row["stimulus"], f"{sheet} row {row['row']} ('{row['stimulus']}')"
        if "_" not in name:
            bad(f"{where}: stimulus name is not <cloud>_<code>")
            continue
        try:
            score = float(row["mos"].replace(",", "."))
        except ValueError:
            bad(f"{where}: MOS {row['mos']!r} is not a number")
            continue
        if not SCORE_RANGE[0] <= score <= SCORE_RANGE[1]:
            bad(f"{where}: MOS {score} outside 1..5")
            continue
        if row["file"]:
            dist = root / row["file"]
            if not dist.is_file():
                bad(f"{where}: file {row['file']} not found under {root}")
                continue
        else:
            dist = _find(root, name)
            if dist is None:
                skipped.append(f"{where}: no file in this copy of the dataset")
                continue
        cloud = name.split("_")[0]
        if cloud not in refs:
            ref = _find(root, cloud, "Original") or _find(root, cloud)
            if ref is None:
                raise MosDataError(f"{root}: no reference cloud '{cloud}' (expected Original/{cloud}.zip)")
            refs[cloud] = ref
        items.append(MosItem("cpcd2", cloud, name, refs[cloud], dist, score))
    if not items:
        raise MosDataError(f"{sheet}: no usable rows ({len(skipped)} skipped)")
    layout = MosLayout("cpcd2", tuple(refs), SCORE_RANGE, True)
    return MosDataset(layout, items, sheet, [], skipped)
