"""SHREC'14 non-rigid humans (real: 40 subjects x 10 poses; synthetic: 15 x 20).

Layout: a folder of meshes (``.obj`` or ``.off``, usually named by a running index such as
``0.obj``..``399.obj`` or ``Data/<id>.off``) and Princeton Shape Benchmark ``.cla`` class files
that assign each mesh id to a class (= subject):

    PSB 1
    <n_classes> <n_models>
    <class name> <parent class> <n members>
    <id>
    <id>
    ...

Mesh ids in the .cla are matched to file stems (``12`` matches ``12.obj``, ``Model12.off``...).
The pose index of a mesh is its position within its class (the .cla order); the canonical
(T-pose) target of a subject can be named per subject with ``canonical_ids``.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from datamodules.canonical.tosca import MeshReadError, read_mesh

MESH_EXTS = (".obj", ".off", ".ply")


@dataclass(frozen=True)
class ShrecItem:
    subject: str
    pose: int
    mesh_id: str
    path: Path


def read_cla(path: str | Path) -> dict[str, list[str]]:
    """Princeton ``.cla`` file -> ``{class name: [model ids in file order]}``."""
    path = Path(path)
    lines = [ln.strip() for ln in path.read_text().splitlines()]
    lines = [ln for ln in lines if ln]
    if not lines or not lines[0].startswith("PSB"):
        raise MeshReadError(f"{path}: not a PSB .cla file (first line must be 'PSB <version>')")
    try:
        n_classes, n_models = (int(x) for x in lines[1].split()[:2])
    except (IndexError, ValueError) as exc:
        raise MeshReadError(f"{path}: bad header line 2 (want '<n_classes> <n_models>')") from exc
    out: dict[str, list[str]] = {}
    i = 2
    for _ in range(n_classes):
        if i >= len(lines):
            raise MeshReadError(f"{path}: truncated: expected {n_classes} classes, found {len(out)}")
        parts = lines[i].split()
        if len(parts) < 3:
            raise MeshReadError(f"{path}: bad class line '{lines[i]}' (want '<name> <parent> <count>')")
        name, count = parts[0], int(parts[2])
        ids = lines[i + 1:i + 1 + count]
        if len(ids) != count:
            raise MeshReadError(f"{path}: class '{name}' lists {len(ids)} of {count} models")
        out[name] = [s.split()[0] for s in ids]
        i += 1 + count
    total = sum(len(v) for v in out.values())
    if total != n_models:
        raise MeshReadError(f"{path}: header says {n_models} models, classes list {total}")
    return out


def write_cla(path: str | Path, classes: dict[str, list[str]]) -> None:
    lines = ["PSB 1", f"{len(classes)} {sum(len(v) for v in classes.values())}", ""]
    for name, ids in classes.items():
        lines += [f"{name} 0 {len(ids)}", *[str(i) for i in ids], ""]
    Path(path).write_text("\n".join(lines))


def _stem_id(stem: str) -> str | None:
    m = re.search(r"(\d+)$", stem)
    return str(int(m.group(1))) if m else None


def index_shrec14(root: str | Path, cla: str | Path | None = None) -> list[ShrecItem]:
    """Mesh files under ``root`` with subjects from the ``.cla`` (default: the only .cla under root)."""
    root = Path(root)
    if not root.is_dir():
        raise MeshReadError(f"{root}: SHREC'14 folder not found")
    if cla is None:
        clas = sorted(root.rglob("*.cla"))
        if len(clas) != 1:
            raise MeshReadError(f"{root}: need exactly one .cla class file (found {len(clas)}); pass cla=")
        cla = clas[0]
    classes = read_cla(cla)
    files: dict[str, Path] = {}
    for p in sorted(root.rglob("*")):
        if p.suffix.lower() in MESH_EXTS and p.is_file():
            k = _stem_id(p.stem)
            if k is not None:
                files.setdefault(k, p)
    items = []
    for subject, ids in classes.items():
        for pose, mid in enumerate(ids):
            key = str(int(mid)) if mid.isdigit() else mid
            if key not in files:
                raise MeshReadError(f"{cla}: model '{mid}' of class '{subject}' has no mesh file under {root}")
            items.append(ShrecItem(subject, pose, mid, files[key]))
    return items


def load(item: ShrecItem):
    """``(V, 3) float64, (F, 3) int64`` of one item."""
    return read_mesh(item.path)
