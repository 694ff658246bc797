"""Real CAD models for the completion data: a folder of meshes, ShapeNetCore, one loader.

Two layouts are indexed here (the Sweet Home 3D catalogues: :mod:`datamodules.completion.sweethome3d`):

* ``data.source=meshes``: ``<root>/<category>/<model>.<ext>`` (one file = one model) or
  ``<root>/<category>/<model>/**/*.<ext>`` (a folder = one model, its files its parts), with
  ``ext`` one of ``.obj .off .ply .stl .glb .gltf``. Every category folder is read: the thesis
  names and their aliases (``sofa``, ``airplane``, ``display``, ``rifle`` ...,
  :data:`lit3d.utils.shapenet_categories.CATEGORY_ALIASES`) are those categories, any other name
  is a user category of that name (:func:`folder_category`).
* ``data.source=shapenet``: ShapeNetCore v1 (``<synset>/<id>/model.obj``) or v2
  (``<synset>/<id>/models/model_normalized.obj``), synsets of the ten thesis categories
  (:data:`SHAPENET_SYNSETS`; rifle and pistol both make ``firearm``).

Every model is +y up (ShapeNet's and Sweet Home 3D's convention; ``up_axis="z"`` turns z-up
folders). :func:`load_model_mesh` concatenates a model's parts into one triangle soup;
:func:`split_models` assigns whole models to the train / val / test groups by a stable hash of
the model id, so no model is in two splits.
"""
from __future__ import annotations

import io
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from datamodules.cache import DataError, stable_int_seed
from datamodules.completion.ac3d import read_ac
from datamodules.completion.md2 import read_md2
from lit3d.utils.shapenet_categories import CATEGORY_ALIASES, SEEN_CATEGORIES, UNSEEN_CATEGORIES

MESH_EXTS = (".obj", ".off", ".ply", ".stl", ".glb", ".gltf")
ALL_CATEGORIES = SEEN_CATEGORIES + UNSEEN_CATEGORIES
# ShapeNetCore synset ids of the thesis categories (3D-RecGAN++ used the same ten)
SHAPENET_SYNSETS: dict[str, str] = {
    "02828884": "bench", "03001627": "chair", "04256520": "couch", "04379243": "table",
    "02958343": "car", "03325088": "faucet", "04090263": "firearm", "03948459": "firearm",
    "03467517": "guitar", "03211117": "monitor", "02691156": "plane",
}


@dataclass(frozen=True)
class CadModel:
    """One real model: where its parts are and what it is.

    ``files`` are paths, or ``<archive>::<member>`` for a part inside a zip catalogue;
    ``rotation`` (9 floats, row-major) and ``size`` (width, height, depth) are applied on load
    when given (Sweet Home 3D's ``modelRotation`` and catalogue size).
    """

    model_id: str
    category: str
    files: tuple[str, ...]
    name: str = ""
    licence: str = ""
    creator: str = ""
    rotation: tuple[float, ...] | None = None
    size: tuple[float, float, float] | None = None
    extra: dict = field(default_factory=dict, compare=False, hash=False)

    def record(self) -> dict:
        """The manifest entry of this model (JSON-ready)."""
        out = {"model_id": self.model_id, "category": self.category, "name": self.name,
               "files": list(self.files), "licence": self.licence, "creator": self.creator}
        return {k: v for k, v in out.items() if v not in ("", None)}


def category_of(name: str) -> str | None:
    """A folder name -> thesis category (aliases and plurals accepted), or None."""
    key = name.strip().lower().replace(" ", "_")
    for cand in (key, key.rstrip("s"), key[:-2] if key.endswith("es") else key):
        cand = CATEGORY_ALIASES.get(cand, cand)
        if cand in ALL_CATEGORIES:
            return cand
    return None


def folder_category(name: str) -> str:
    """A category folder's name -> its category: the thesis category (:func:`category_of`), else the
    name itself in lower case with spaces as underscores (a user category: ``My Animals`` -> ``my_animals``)."""
    return category_of(name) or name.strip().lower().replace(" ", "_")


def category_folders(root: str | Path) -> dict[str, list[Path]]:
    """``{category: [its folders]}`` of the category folders under ``root`` (hidden ones left out)."""
    out: dict[str, list[Path]] = {}
    for d in sorted(p for p in _folder(root, "mesh").iterdir() if p.is_dir() and not p.name.startswith(".")):
        out.setdefault(folder_category(d.name), []).append(d)
    return out


def _folder(root: str | Path, what: str) -> Path:
    root = Path(root)
    if not root.is_dir():
        raise DataError(f"{root}: {what} folder not found (set data.root=PATH)")
    return root


def index_mesh_folder(root: str | Path) -> tuple[list[CadModel], list[dict]]:
    """Models of a ``<root>/<category>/...`` folder -> (models, dropped entries with reasons: entries
    without a mesh file). Every category folder is read (:func:`folder_category`)."""
    root = _folder(root, "mesh")
    models, dropped = [], []
    for category, cat_dir in ((c, d) for c, ds in category_folders(root).items() for d in ds):
        for entry in sorted(cat_dir.iterdir()):
            if entry.name.startswith("."):
                continue
            if entry.is_dir():
                parts = sorted(str(p) for p in entry.rglob("*") if p.suffix.lower() in MESH_EXTS)
            else:
                parts = [str(entry)] if entry.suffix.lower() in MESH_EXTS else []
            if not parts:
                if entry.is_dir() or entry.suffix.lower() not in (".mtl", ".png", ".jpg", ".txt", ".json"):
                    dropped.append({"path": str(entry), "reason": f"no mesh file ({' '.join(MESH_EXTS)})"})
                continue
            models.append(CadModel(f"{category}/{entry.stem if entry.is_file() else entry.name}", category,
                                   tuple(parts), name=entry.name))
    if not models:
        raise DataError(f"{root}: no models found; expected <root>/<category>/<model>.obj (any category name; "
                        f"{' '.join(MESH_EXTS)})")
    return models, dropped


def index_shapenet(root: str | Path) -> tuple[list[CadModel], list[dict]]:
    """Models of a ShapeNetCore v1 or v2 folder (the thesis synsets) -> (models, dropped)."""
    root = _folder(root, "ShapeNetCore")
    models, dropped = [], []
    synsets = sorted(p for p in root.iterdir() if p.is_dir() and p.name.isdigit())
    for syn in synsets:
        category = SHAPENET_SYNSETS.get(syn.name)
        if category is None:
            dropped.append({"path": str(syn), "reason": "synset not among the thesis categories"})
            continue
        for mdir in sorted(p for p in syn.iterdir() if p.is_dir()):
            for rel in ("models/model_normalized.obj", "model.obj"):
                if (mdir / rel).is_file():
                    models.append(CadModel(f"{syn.name}/{mdir.name}", category, (str(mdir / rel),), name=mdir.name))
                    break
            else:
                dropped.append({"path": str(mdir), "reason": "no model.obj or models/model_normalized.obj"})
    if not models:
        raise DataError(f"{root}: no ShapeNetCore models found; expected <synset>/<model_id>/model.obj (v1) "
                        f"or <synset>/<model_id>/models/model_normalized.obj (v2), synsets {sorted(SHAPENET_SYNSETS)}")
    return models, dropped


def _read_part(spec: str):
    """One part file (or ``archive::member``) -> trimesh.Trimesh (materials skipped)."""
    import trimesh

    suffix = spec.rsplit(".", 1)[-1].lower()
    if suffix in ("ac", "acc"):  # formats trimesh does not read: the project's readers
        return read_ac(spec)
    if suffix == "md2":
        return read_md2(spec)
    if "::" in spec:
        archive, member = spec.split("::", 1)
        with zipfile.ZipFile(archive) as z:
            data = z.read(member)
        return trimesh.load(io.BytesIO(data), file_type=Path(member).suffix.lstrip(".").lower(), force="mesh",
                            process=False, skip_materials=True)
    return trimesh.load(spec, force="mesh", process=False, skip_materials=True)


def load_model_mesh(model: CadModel, up_axis: str = "y"):
    """A model's parts as one trimesh (float64 vertices, +y up), rotation and size applied.

    Raises:
        DataError: naming the file when a part is unreadable or the model has no triangle.
    """
    import trimesh

    parts = []
    for spec in model.files:
        try:
            mesh = _read_part(spec)
        except Exception as exc:  # trimesh raises many types on bad files
            raise DataError(f"{spec}: unreadable mesh ({type(exc).__name__}: {exc})") from exc
        if isinstance(mesh, trimesh.Trimesh) and len(mesh.faces):
            parts.append(mesh)
    if not parts:
        raise DataError(f"{model.files[0]}: model {model.model_id} has no triangles")
    mesh = trimesh.util.concatenate(parts) if len(parts) > 1 else parts[0]
    v = np.asarray(mesh.vertices, np.float64)
    f = np.asarray(mesh.faces, np.int64)
    ok = np.isfinite(v).all(axis=1)
    if not ok.all():
        f = f[ok[f].all(axis=1)]
    if not len(f):
        raise DataError(f"{model.files[0]}: model {model.model_id} has no finite triangle")
    if up_axis == "z":
        v = v[:, [0, 2, 1]] * [1.0, 1.0, -1.0]
    elif up_axis != "y":
        raise DataError(f"data.meshes.up_axis={up_axis!r}: expected 'y' or 'z'")
    if model.rotation is not None:
        v = v @ np.asarray(model.rotation, np.float64).reshape(3, 3).T
    if model.size is not None:
        used = np.unique(f)
        ext = v[used].max(0) - v[used].min(0)
        target = np.asarray(model.size, np.float64)
        if np.all(ext > 0) and np.all(target > 0):
            v = v * (target / ext)
    return trimesh.Trimesh(v, f, process=False)


def split_models(models: list[CadModel], fractions: dict[str, float], seed: int) -> dict[str, str]:
    """``{model_id: group}`` with group in ``fractions`` (e.g. train/val/test), per category.

    Within a category the models are ordered by a stable hash of (seed, id) and cut by the
    fractions (every group with a positive fraction gets at least one model when there are
    enough), so the assignment depends only on the ids, not on the listing order.
    """
    groups = [g for g, f in fractions.items() if f > 0]
    total = sum(fractions[g] for g in groups)
    out: dict[str, str] = {}
    by_cat: dict[str, list[CadModel]] = {}
    for m in models:
        by_cat.setdefault(m.category, []).append(m)
    for ms in by_cat.values():
        ms = sorted(ms, key=lambda m: stable_int_seed(seed, "model-split", m.model_id))
        n = len(ms)
        counts = [int(round(n * fractions[g] / total)) for g in groups]
        if n >= len(groups):
            counts = [max(1, c) for c in counts]
        while sum(counts) > n:
            counts[int(np.argmax(counts))] -= 1
        counts[0] += n - sum(counts)
        start = 0
        for g, c in zip(groups, counts):
            for m in ms[start:start + c]:
                out[m.model_id] = g
            start += c
    return out
