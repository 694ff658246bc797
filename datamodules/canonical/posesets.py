"""Real pose sets of people and animals: FAUST registrations and Sumner & Popovic's animals.

FAUST (Bogo et al. 2014): a folder of meshes whose names give subject and pose, in any of the
published or common layouts (``.off``, ``.ply`` or ``.obj``):

    subject<S>_pose<P>.<ext>        e.g. subject3_pose7.off (the remeshed copy in ../shared/data/faust_a)
    tr_reg_<NNN>.<ext>, <NNN>.<ext> NNN = 10 * S + P (the FAUST registrations and their remeshes)

Pose P is the same body pose for every subject. Meshes are read without merging vertices (some
remeshed files hold distinct vertices at one position). FAUST has no rest pose: the canonical
pose is one of the ten (``canonical_pose``, default 0, the standing pose).

Sumner & Popovic (deformation transfer, SIGGRAPH 2004): ``<animal>/<animal>-reference.obj`` (the
rest pose = the canonical pose, index 0 here) and ``<animal>/<animal>-<NN>.obj`` (pose NN >= 1).

Both are +y up and face +z, as lit3d renders them. :func:`index_faust` and :func:`index_sumner`
return ``{(subject, pose): path}``; a folder with no matching file is a :class:`MeshReadError`
naming it.
"""
from __future__ import annotations

import re
from pathlib import Path

from datamodules.canonical.tosca import MeshReadError

FAUST_EXTS = (".off", ".ply", ".obj")
_FAUST_NAMED = re.compile(r"^subject(\d+)_pose(\d+)$", re.IGNORECASE)
_FAUST_NUMBERED = re.compile(r"^(?:tr_reg_|test_scan_|tr_scan_)?(\d{3})$", re.IGNORECASE)
_SUMNER = re.compile(r"^(?P<animal>[a-z]+)-(?P<pose>reference|\d+)$", re.IGNORECASE)


def faust_subject_pose(path: str | Path) -> tuple[int, int] | None:
    """(subject, pose) from a FAUST file name, or None when the name is not a FAUST one."""
    stem = Path(path).stem
    m = _FAUST_NAMED.match(stem)
    if m:
        return int(m.group(1)), int(m.group(2))
    m = _FAUST_NUMBERED.match(stem)
    if m:
        n = int(m.group(1))
        return n // 10, n % 10
    return None


def _folder(root: str | Path, what: str) -> Path:
    root = Path(root)
    if not root.is_dir():
        raise MeshReadError(f"{root}: {what} folder not found")
    return root


def index_faust(root: str | Path) -> dict[tuple[str, int], Path]:
    """``{("subject<S>", P): path}`` of every FAUST mesh under ``root`` (recursively); a shape
    found twice (two formats) keeps the first of ``FAUST_EXTS``."""
    root = _folder(root, "FAUST")
    rank = {e: i for i, e in enumerate(FAUST_EXTS)}
    best: dict[tuple[str, int], Path] = {}
    for p in sorted(root.rglob("*")):
        ext = p.suffix.lower()
        sp = faust_subject_pose(p) if ext in rank and p.is_file() else None
        if sp is None:
            continue
        key = (f"subject{sp[0]}", sp[1])
        if key not in best or rank[ext] < rank[best[key].suffix.lower()]:
            best[key] = p
    if not best:
        raise MeshReadError(f"{root}: no FAUST meshes (subject<S>_pose<P>, tr_reg_<NNN> or <NNN> "
                            f"with {', '.join(FAUST_EXTS)}) found")
    return best


def index_sumner(root: str | Path, animals: list[str] | None = None) -> dict[tuple[str, int], Path]:
    """``{(animal, pose): path}`` of the Sumner pose sets under ``root``; pose 0 = the reference
    (rest) pose. An animal without a reference file is an error naming it."""
    root = _folder(root, "Sumner pose-set")
    items: dict[tuple[str, int], Path] = {}
    for p in sorted(root.rglob("*.obj")):
        m = _SUMNER.match(p.stem)
        if not m or (animals and m.group("animal") not in animals):
            continue
        pose = 0 if m.group("pose").lower() == "reference" else int(m.group("pose"))
        if pose == 0 and m.group("pose").lower() != "reference":
            raise MeshReadError(f"{p}: pose number 0 is reserved for <animal>-reference.obj")
        items[(m.group("animal").lower(), pose)] = p
    if not items:
        raise MeshReadError(f"{root}: no Sumner pose sets (<animal>/<animal>-reference.obj, <animal>-NN.obj) found")
    missing = sorted({a for a, _ in items} - {a for a, k in items if k == 0})
    if missing:
        raise MeshReadError(f"{root}: no reference pose (<animal>-reference.obj) for {', '.join(missing)}")
    return items
