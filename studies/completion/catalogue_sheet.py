"""Contact sheet of the real models a completion data folder used in one split, as shaded renders.

    python -m studies.completion.catalogue_sheet DATA_DIR --split test_unseen --categories plane car firearm --per 4 \\
        --out docs/images/unseen_real_models.png

DATA_DIR is a prepared completion folder of a real source (``data.source=installed | sweethome3d |
meshes | shapenet``): its manifest names every model and the split that used it. Each row is one model
in the project's frame (+y up, front +z) after the source's rotation, seen from the front, the side,
three-quarter and above, labelled with its id, category, licence and author.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import trimesh

from datamodules.completion.cad_models import load_model_mesh
from datamodules.completion.meshes import index_models
from lit3d.geometry.normalise import normalise_vertices
from lit3d.render.shaded import shaded_views
from lit3d.utils.figures import labelled_grid

VIEWS = {"front": (0.0, 0.0, 1.0), "side": (1.0, 0.0, 0.0), "three-quarter": (0.8, 0.6, 1.0), "above": (0.0, 1.0, 0.001)}


def unit_box(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """The mesh centred and scaled so that its longest side spans 1.6 (inside the renders' +-0.9 extent)."""
    return trimesh.Trimesh(normalise_vertices(mesh.vertices, None)[0] * 1.6, mesh.faces, process=False)


def wrapped(text: str, width: int = 44) -> list[str]:
    """``text`` in lines of at most ``width`` characters, broken after a '/' where one falls."""
    lines = []
    while len(text) > width:
        cut = text.rfind("/", 0, width) + 1 or width
        lines.append(text[:cut])
        text = text[cut:]
    return [*lines, text]


def used_models(data_dir: Path, split: str, categories: list[str], per: int) -> list[dict]:
    """Up to ``per`` model records per category among those ``split`` used, in model-id order."""
    manifest = json.loads((data_dir / "manifest.json").read_text())
    used = {it["model_id"] for it in manifest["items"] if it["split"] == split and it.get("model_id")}
    chosen = []
    for cat in categories:
        recs = sorted((m for m in manifest["models"] if m["model_id"] in used and m["category"] == cat),
                      key=lambda m: m["model_id"])
        step = max(len(recs) // per, 1)  # spread over the catalogue, not the first few of one package
        chosen += recs[::step][:per]
    return chosen


def main(argv: list[str] | None = None) -> Path:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("data_dir", type=Path)
    ap.add_argument("--split", default="test_unseen")
    ap.add_argument("--categories", nargs="+", default=["plane", "car", "firearm"])
    ap.add_argument("--per", type=int, default=4, help="models per category")
    ap.add_argument("--cell", type=int, default=256)
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args(argv)
    config = json.loads((args.data_dir / "manifest.json").read_text())["config"]
    by_id = {m.model_id: m for m in index_models(config["source"], config.get("root"))[0]}  # with their rotations
    rows = []
    for rec in used_models(args.data_dir, args.split, args.categories, args.per):
        model = by_id[rec["model_id"]]
        cells = shaded_views(unit_box(load_model_mesh(model)), np.array(list(VIEWS.values())), size=args.cell)
        label = "\n".join(line[:44] for line in (*wrapped(model.model_id), model.category, model.licence,
                                                  str(model.creator)))
        rows.append({"label": label, "cells": list(cells)})
    title = f"Real models of {args.data_dir.name}, split {args.split} ({', '.join(args.categories)})"
    img = labelled_grid(rows, list(VIEWS), title, args.cell, left=420)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    img.save(args.out)
    print(args.out)
    return args.out


if __name__ == "__main__":
    main()
