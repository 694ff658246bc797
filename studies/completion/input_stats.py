"""Statistics of completion inputs against their targets: do synthetic inputs look like real ones?

A study (``python -m studies.completion.input_stats``), not part of the data pipeline: it calibrated the
``recgan`` sensor of :mod:`lit3d.sensing.sensor` against the released 3D-RecGAN++ sample.

Per pair of a 2.5D surface grid and its complete target (both ``(R, R, R) bool``):

- ``inside``: share of surface voxels that are target voxels;
- ``outside_dist``: mean distance (voxels) from an outside surface voxel to the target (0 when
  none is outside);
- ``input_iou``: IoU of the network input (surface max-pooled by ``input_factor``, upsampled
  back) with the target: the input-as-prediction baseline of the evaluation;
- ``fill``: share of the grid the target fills;
- ``surface_ratio``: surface voxels per target voxel;
- ``coverage``: share of the target's ``(i, j)`` columns that hold a surface voxel (holes and
  missed parts lower it).

``recgan_rows`` reads a 3D-RecGAN++ folder (its pairs pooled from 256^3 to ``R``);
``synthetic_rows`` generates seen-category samples with a sensor of
:mod:`lit3d.sensing.sensor`; ``cad_rows`` does the same with real CAD models
(``--cad sweethome3d``, ``--cad meshes=DIR``, ``--cad shapenet=DIR``).
``python -m studies.completion.input_stats --real ROOT`` prints them side by side per resolution
(the README's calibration table), then per category.
"""
from __future__ import annotations

import argparse
import json
from collections.abc import Iterable, Sequence

import numpy as np
from scipy import ndimage

from datamodules.cache import stable_seed
from datamodules.completion.depth_voxels import VIEW_SETS, make_sample
from datamodules.completion.furniture import make_shape
from datamodules.completion.mesh_shapes import mesh_shape
from datamodules.completion.meshes import index_models
from datamodules.completion.recgan import convert_pair, index_recgan
from datamodules.completion.voxel_cache import max_pool_bool
from lit3d.utils.io import atomic_write_text
from lit3d.utils.tables import markdown_table as markdown

STATS = ("inside", "outside_dist", "input_iou", "fill", "surface_ratio", "coverage")


def pair_statistics(surface: np.ndarray, target: np.ndarray, input_factor: int = 4) -> dict[str, float]:
    """The statistics of one ``(R, R, R) bool`` surface/target pair (see the module doc)."""
    n_surf = int(surface.sum())
    inside = surface & target
    out = surface & ~target
    dist = float(ndimage.distance_transform_edt(~target)[out].mean()) if out.any() else 0.0
    pooled = max_pool_bool(surface, input_factor)
    up = pooled.repeat(input_factor, 0).repeat(input_factor, 1).repeat(input_factor, 2)
    union = int((up | target).sum())
    cols = target.any(2)
    return {
        "inside": inside.sum() / max(n_surf, 1),
        "outside_dist": dist,
        "input_iou": (up & target).sum() / max(union, 1),
        "fill": float(target.mean()),
        "surface_ratio": n_surf / max(int(target.sum()), 1),
        "coverage": (surface.any(2) & cols).sum() / max(int(cols.sum()), 1),
    }


def recgan_rows(root: str, res: int, input_factor: int = 4, raw_res: int = 256) -> list[dict]:
    """One row (category, split folder, name + :data:`STATS`) per pair of a 3D-RecGAN++ folder."""
    pairs, _ = index_recgan(root)
    rows = []
    for p in pairs:
        surface, target = convert_pair(p, raw_res=raw_res, target_res=res, input_res=res)
        rows.append({"category": p.category, "folder": p.folder, "name": p.name,
                     **pair_statistics(surface, target, input_factor)})
    return rows


def synthetic_rows(res: int, sensor, per_category: int = 6, seed: int = 0, input_factor: int = 4,
                   categories: Sequence[str] = ("bench", "chair", "couch", "table"),
                   view_set: str = "same") -> list[dict]:
    """Rows for ``per_category`` synthetic samples (one shape and one random view each) per category."""
    views = VIEW_SETS[view_set]
    rows = []
    for category in categories:
        for i in range(per_category):
            rng = np.random.default_rng(stable_seed(seed, "input_stats", category, i))
            shape = make_shape(category, rng)
            s = make_sample(shape, views[int(rng.integers(len(views)))], target_res=res, input_factor=input_factor,
                            sensor=sensor, rng=rng)
            rows.append({"category": category, "folder": view_set, "name": f"{category}_{i}",
                         **pair_statistics(s["surface"], s["target"], input_factor)})
    return rows


def cad_rows(res: int, sensor, source: str = "sweethome3d", root: str | None = None, per_category: int = 6,
             seed: int = 0, input_factor: int = 4, categories: Sequence[str] = ("bench", "chair", "couch", "table"),
             view_set: str = "same") -> list[dict]:
    """Rows for up to ``per_category`` real models per category (seeded pick, one random view each)."""
    models, _ = index_models(source, root)
    views = VIEW_SETS[view_set]
    rows = []
    for category in categories:
        ms = sorted((m for m in models if m.category == category), key=lambda m: m.model_id)
        rng = np.random.default_rng(stable_seed(seed, "input_stats_cad", category))
        for m in (ms[i] for i in rng.permutation(len(ms))[:per_category]):
            s = make_sample(mesh_shape(m), views[int(rng.integers(len(views)))], target_res=res,
                            input_factor=input_factor, sensor=sensor, rng=rng)
            rows.append({"category": category, "folder": view_set, "name": m.model_id,
                         **pair_statistics(s["surface"], s["target"], input_factor)})
    return rows


def category_table(columns: dict[str, list[dict]], stats: Sequence[str] = ("fill", "input_iou", "inside", "coverage")) -> str:
    """A markdown table of per-category means (``n`` rows in brackets), one column per named row set."""
    names = list(columns)
    cats = sorted({r["category"] for rows in columns.values() for r in rows})
    out = []
    for cat in cats:
        for k in stats:
            cells = []
            for n in names:
                v = [r[k] for r in columns[n] if r["category"] == cat]
                cells.append(f"{np.mean(v):.3f} ({len(v)})" if v else "–")
            out.append([cat, k, *cells])
    return markdown(["category", "statistic", *names], out)


def summary(rows: Iterable[dict]) -> dict[str, tuple[float, float, float, float]]:
    """Per statistic: ``(mean, sd, min, max)`` over the rows."""
    rows = list(rows)
    out = {}
    for k in STATS:
        v = np.array([r[k] for r in rows], dtype=np.float64)
        out[k] = (float(v.mean()), float(v.std(ddof=1)) if len(v) > 1 else 0.0, float(v.min()), float(v.max()))
    return out


def markdown_table(columns: dict[str, dict]) -> str:
    """A markdown table, one column per named summary, ``mean ± sd [min, max]`` per statistic."""
    names = list(columns)
    rows = [[k, *(f"{m:.3f} ± {s:.3f} [{lo:.3f}, {hi:.3f}]" for m, s, lo, hi in (columns[n][k] for n in names))]
            for k in STATS]
    return markdown(["statistic", *names], rows)


def write_fixture(path: str, root: str, res: int, input_factor: int = 4) -> None:
    """Save the per-pair statistics of a 3D-RecGAN++ folder (numbers only, no grids) as JSON."""
    rows = [{k: (round(float(v), 6) if k in STATS else v) for k, v in r.items()}
            for r in recgan_rows(root, res, input_factor)]
    atomic_write_text(path, json.dumps({"source": str(root), "res": res, "input_factor": input_factor,
                                        "rows": rows}, indent=1))


def compare(synthetic: Sequence[dict], real: Sequence[dict], z: float = 2.5,
            floor: float = 0.01) -> dict[str, tuple[float, float, bool]]:
    """Per statistic: ``(synthetic mean - real mean, tolerance, within)``; the tolerance is ``z``
    standard errors of the difference of the two means (independent samples), at least ``floor``."""
    out = {}
    for k in STATS:
        a = np.array([r[k] for r in synthetic], dtype=np.float64)
        b = np.array([r[k] for r in real], dtype=np.float64)
        se = np.sqrt(a.var(ddof=1) / len(a) + b.var(ddof=1) / len(b))
        diff, tol = float(a.mean() - b.mean()), max(z * float(se), floor)
        out[k] = (diff, tol, abs(diff) <= tol)
    return out


def main(argv: list[str] | None = None) -> None:
    """Print the real sample's statistics beside those of synthetic sets per resolution."""
    ap = argparse.ArgumentParser(prog="python -m studies.completion.input_stats", description=main.__doc__)
    ap.add_argument("--real", required=True, help="3D-RecGAN++ folder (e.g. ../shared/data/recgan_sample)")
    ap.add_argument("--res", type=int, nargs="+", default=[64, 256], help="grid sides to compare at")
    ap.add_argument("--sensor", nargs="+", default=["ortho", "recgan"], help="synthetic sensors (names)")
    ap.add_argument("--per-category", type=int, default=12)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cad", nargs="*", default=[], metavar="SOURCE[=ROOT]",
                    help="real CAD columns: sweethome3d (installed catalogues), meshes=DIR, shapenet=DIR")
    ap.add_argument("--write-fixture", metavar="JSON", help="only save the real folder's per-pair statistics "
                    "at the first --res to JSON (the tests' committed fixture)")
    args = ap.parse_args(argv)
    if args.write_fixture:
        write_fixture(args.write_fixture, args.real, args.res[0])
        return
    for res in args.res:
        rows = {"3D-RecGAN++ (real)": recgan_rows(args.real, res)}
        for name in args.sensor:
            rows[f"synthetic, {name}"] = synthetic_rows(res, name, args.per_category, args.seed)
        for spec in args.cad:
            source, _, root = spec.partition("=")
            for name in args.sensor:
                rows[f"{source}, {name}"] = cad_rows(res, name, source, root or None, args.per_category, args.seed)
        cols = {k: summary(v) for k, v in rows.items()}
        print(f"\n### R = {res}\n\n{markdown_table(cols)}\n\n#### per category, R = {res}\n\n{category_table(rows)}")


if __name__ == "__main__":
    main()
