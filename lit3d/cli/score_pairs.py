"""``lit3d-score --pairs``: which pairs to score, and the one table of their scores.

Two ways to name the pairs:

- ``--pairs FILE.tsv``: one pair a line, ``reference<TAB>distorted`` (two fields separated by white
  space also do when neither path holds a space). Empty lines, lines starting with ``#`` and a
  first line ``ref<TAB>dist`` / ``reference<TAB>distorted`` (a header) are skipped, also after a
  UTF-8 byte-order mark. Relative paths are relative to the TSV file's folder. A file name that is
  not UTF-8 (Latin-1 bytes) is kept byte for byte (``surrogateescape``), as the file system has it.
- ``--pairs REF_DIR DIST_DIR``: every file of ``DIST_DIR`` with a file of the same name stem in
  ``REF_DIR`` (``targets/chair_01.obj`` with ``predictions/chair_01.npz``), in name order; files
  without a partner are named in a note.

Every path is checked before anything is loaded or rendered: a missing file, a folder, a FIFO (never
opened), a bad line or a folder with no pair is one ``ValueError`` naming the file (and line), in the
wording of every command (:func:`lit3d.utils.files.path_problem`).
"""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from lit3d.utils.files import path_problem, shown
from lit3d.utils.tables import markdown_table

HEADERS = ({"ref", "dist"}, {"reference", "distorted"})
SHOWN_EXTRA = ("chamfer", "hausdorff", "y_psnr", "pcqm")


def read_pairs(spec: Sequence[str]) -> tuple[list[tuple[Path, Path]], list[str]]:
    """``([(reference, distorted), ...], notes)`` from ``--pairs``'s arguments (one TSV file or two folders)."""
    if len(spec) == 1:
        path = Path(spec[0])
        if path.is_dir():
            raise ValueError(f"--pairs {path}: a folder; give a .tsv file of pairs, or two folders (REF_DIR DIST_DIR)")
        return pairs_from_tsv(path), []
    if len(spec) == 2:
        return pairs_from_folders(Path(spec[0]), Path(spec[1]))
    raise ValueError(f"--pairs takes one .tsv file or two folders (REF_DIR DIST_DIR), got {len(spec)} arguments")


def pairs_from_tsv(path: Path) -> list[tuple[Path, Path]]:
    """The pairs of a TSV file (see the module doc); paths resolved against the file's folder."""
    problem = path_problem(path)
    if problem is not None:  # a FIFO is never opened
        raise ValueError(f"{path}: {problem} (--pairs)")
    pairs = []
    for number, line in _text_lines(path):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        fields = [f.strip() for f in line.split("\t")] if "\t" in line else line.split()
        fields = [f for f in fields if f]
        if len(fields) != 2:
            raise ValueError(f"{path} line {number}: expected 2 tab-separated fields (reference, distorted), "
                             f"got {len(fields)}")
        if not pairs and {f.lower() for f in fields} in HEADERS:
            continue
        ref, dist = ((path.parent / f) for f in fields)
        for shape in (ref, dist):
            problem = path_problem(shape)
            if problem is not None:
                raise ValueError(f"{path} line {number}: {shown(shape)}: {problem}")
        pairs.append((ref, dist))
    if not pairs:
        raise ValueError(f"{path}: no pairs (one 'reference<TAB>distorted' a line)")
    return pairs


def _text_lines(path: Path) -> list[tuple[int, str]]:
    """``(number, line)`` of a pairs file: a UTF-8 byte-order mark is dropped; a line that is not
    UTF-8 (a Latin-1 file name) is read with its bytes kept (``surrogateescape``), so the file it
    names is found as it is on disk; a file with NUL bytes is not a text file (the first such line named)."""
    data = path.read_bytes()
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    out = []
    for number, raw in enumerate(data.splitlines(), 1):
        if b"\0" in raw:
            raise ValueError(f"{path} line {number}: not a text file of pairs (a NUL byte)")
        out.append((number, raw.decode("utf-8", "surrogateescape")))
    return out


def pairs_from_folders(ref_dir: Path, dist_dir: Path) -> tuple[list[tuple[Path, Path]], list[str]]:
    """Files of ``dist_dir`` paired with the file of the same stem in ``ref_dir``, and notes on the
    files left without a partner."""
    refs, dists = _by_stem(ref_dir), _by_stem(dist_dir)
    common = sorted(set(refs) & set(dists))
    if not common:
        raise ValueError(f"--pairs {ref_dir} {dist_dir}: no file name stem is in both folders "
                         f"({len(refs)} and {len(dists)} files)")
    notes = []
    for folder, names in ((ref_dir, refs), (dist_dir, dists)):
        alone = sorted(set(names) - set(common))
        if alone:
            shown = ", ".join(names[s].name for s in alone[:5]) + (", ..." if len(alone) > 5 else "")
            notes.append(f"{len(alone)} file(s) of {folder} have no partner and are not scored: {shown}")
    return [(refs[s], dists[s]) for s in common], notes


def _by_stem(folder: Path) -> dict[str, Path]:
    if not folder.is_dir():
        raise ValueError(f"{folder}: not a folder (--pairs REF_DIR DIST_DIR)")
    out: dict[str, Path] = {}
    for p in sorted(folder.iterdir()):
        if p.is_file() and not p.name.startswith("."):
            if p.stem in out:
                raise ValueError(f"{folder}: {out[p.stem].name} and {p.name} have the same stem; "
                                 "keep one file per shape name")
            out[p.stem] = p
    return out


def pairs_table(rows: Sequence[dict]) -> str:
    """Markdown table, one row per scored pair (``rows``: the per-pair JSON documents of lit3d-score)."""
    predicted = any("predicted_score" in r for r in rows)
    extra = [k for k in SHOWN_EXTRA if any(k in r["features"] for r in rows)]
    head = ["#", "reference", "distorted", "mean Mask-SSIM"] + (["predicted"] if predicted else []) + extra + ["s"]
    body = []
    for i, r in enumerate(rows, 1):
        cells = [str(i), r["ref"], r["dist"], f"{r['overall_score']:.4f}"]
        if predicted:
            cells.append(f"{r['predicted_score']:.4f}" if "predicted_score" in r else "–")
        cells += [f"{r['features'][k]:.5f}" if k in r["features"] else "–" for k in extra]
        cells.append("cached" if r["cached"] else f"{r['seconds']:.1f}")
        body.append(cells)
    return markdown_table(head, body)
