"""``lit3d-reconstruct IMAGE --body --out DIR``: fit the Anny body model to a person's depth image.

Per input NAME, DIR gets (written together, as one set: :func:`lit3d.reconstruct.outputs.write_outputs`):

- ``NAME_body.<fmt>``: the fitted body in the input's pose, camera frame (x right, y down,
  z forward), metres: it overlays the input points;
- ``NAME_body_canonical.<fmt>``: the same mesh topology in Anny's rest pose (y up, metres);
- ``NAME_body_canonical_depth.npy``: ``(128, 128) float32`` canonical depth image, rendered as the
  canonical task renders its Anny targets (:mod:`lit3d.body_fit.results`);
- ``NAME_body.png``: input points | fit and points (camera view, side view) | canonical body;
- ``NAME_body.json``: parameters, fit quality (``poor_fit``), timings, camera, request key.

The fit starts from a body regressor's prediction (:mod:`lit3d.body_fit.regressor`; the zoo's
``body-regressor``, :mod:`lit3d.zoo`, or ``--body-init CKPT``; :func:`start_regressor`), refined by fewer steps
(:func:`lit3d.body_fit.regressor.fit_from_regressor`; ``--body-refine-poor N``: N more steps where those end
flagged poor), or with ``--body-init none`` from the mean body (:mod:`lit3d.body_fit.fit`). A poor fit (not a
person, a bad cut) is written with ``poor_fit: true`` and said on one line.
"""
from __future__ import annotations

import io
import json
import time
from pathlib import Path

import numpy as np

from lit3d.body_fit.fit import fit_body
from lit3d.body_fit.model import Body  # noqa: F401 (re-exported for lit3d.cli.reconstruct)
from lit3d.body_fit.depth_points import observe
from lit3d.body_fit.regressor import Regressor, fit_from_regressor, load_regressor, refine_config
from lit3d.body_fit.results import BodyOutputs, fit_outputs
from lit3d.geometry.normalise import bounding_frame
from lit3d.reconstruct.depth_io import find_mask, read_depth_info, read_mask
from lit3d.reconstruct.figure import LABEL_PX, mesh_panels, points_panels
from lit3d.reconstruct.outputs import finished_set, mesh_bytes, output_files, request_key, write_outputs
from lit3d.reconstruct.pipeline import Options, cut_object
from lit3d.utils.figures import font
from lit3d.zoo import ZOO, zoo_model

ZOO_REGRESSOR = "body-regressor"


def start_regressor(body_init: str | None) -> Regressor | None:
    """The fit's start for ``--body-init``: None -> the zoo's ``body-regressor`` (:mod:`lit3d.zoo`), ``none`` ->
    the mean body (returns None), a path -> that regressor checkpoint. A bad file is one line naming it."""
    if body_init is not None and str(body_init).lower() == "none":
        return None
    if body_init is None:
        return load_regressor(zoo_model(ZOO_REGRESSOR).path)
    return load_regressor(body_init)


def start_label(regressor: Regressor | None) -> str:
    """The console's and the summary's name of the fit's start."""
    if regressor is None:
        return "mean body (--body-init none)"
    zoo = ZOO[ZOO_REGRESSOR].path
    shipped = Path(regressor.path).resolve() == zoo
    return f"body regressor {'shipped ' + ZOO_REGRESSOR + ' (' + str(zoo) + ')' if shipped else regressor.path}"


FLIP = np.array([1.0, -1.0, -1.0])  # camera frame (y down, z forward) <-> GL (y up, z back)
VIEWS = {"camera view": (0.0, 0.0, 1.0), "side view": (1.0, 0.15, 0.1)}


def body_files(name: str, fmt: str, figure: bool = True) -> list[str]:
    """The file names input ``name`` gives with ``--body`` (see the module doc)."""
    return [f"{name}_body.{fmt}", f"{name}_body_canonical.{fmt}", f"{name}_body_canonical_depth.npy"] \
        + ([f"{name}_body.png"] if figure else []) + [f"{name}_body.json"]


def planned_files(args, name: str) -> list[str]:
    """The files of input ``name`` for this command line (``--body`` or the completion chain)."""
    fig = not args.no_figure
    return body_files(name, args.format, fig) if args.body else output_files(name, args.format, fig)


def is_finished(args, name: str, key: str) -> bool:
    """True when ``name``'s set for this command line is whole in ``--out`` with request ``key``."""
    if not args.body:
        return finished_set(args.out, name, args.format, not args.no_figure, key)
    out = Path(args.out)
    if not all((out / f).is_file() for f in body_files(name, args.format, not args.no_figure)):
        return False
    try:
        return json.loads((out / f"{name}_body.json").read_text("utf-8")).get("request") == key
    except (OSError, ValueError, AttributeError):
        return False


def _mesh_bytes(verts: np.ndarray, faces: np.ndarray, fmt: str) -> bytes:
    import trimesh

    return mesh_bytes(trimesh.Trimesh(verts, faces, process=False), fmt)


def _npy_bytes(arr: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, arr)
    return buf.getvalue()


def _normalised(verts_gl: np.ndarray, faces: np.ndarray):
    """A trimesh of GL-frame ``verts`` centred on its bounding box, longest side 1; centre, scale."""
    import trimesh

    centre, scale = bounding_frame(verts_gl)
    return trimesh.Trimesh((verts_gl - centre) * scale, faces, process=False), centre, scale


def _overlay(mesh_tile: np.ndarray, point_tile: np.ndarray) -> np.ndarray:
    """Points (non-black pixels of ``point_tile``) drawn half-transparent over a mesh render."""
    hit = point_tile.sum(-1, keepdims=True) > 0
    return np.where(hit, 0.45 * mesh_tile + 0.55 * point_tile, mesh_tile).astype(np.uint8)


def body_figure(points: np.ndarray, out: BodyOutputs, title: str, size: int = 256) -> bytes:
    """PNG bytes: input points | fit + points (camera view) | fit + points (side view) | canonical body."""
    from PIL import Image, ImageDraw

    posed, centre, scale = _normalised(out.posed * FLIP, out.faces)
    pts = (points * FLIP - centre) * scale
    dirs = np.array([np.asarray(v) / np.linalg.norm(v) for v in VIEWS.values()])
    pt_tiles = points_panels(pts, dirs, size)
    mesh_tiles = mesh_panels(posed, dirs, size)
    canon, _, _ = _normalised(out.canonical, out.faces)
    tiles = [(pt_tiles[0], "input points (camera view)"),
             (_overlay(mesh_tiles[0], pt_tiles[0]), "fitted body + points: camera"),
             (_overlay(mesh_tiles[1], pt_tiles[1]), "fitted body + points: side"),
             (mesh_panels(canon, dirs[:1], size)[0], "canonical body (rest pose)")]
    gap, head = 4, 26
    sheet = Image.new("RGB", (len(tiles) * size + (len(tiles) - 1) * gap, head + LABEL_PX + size), (255, 255, 255))
    draw = ImageDraw.Draw(sheet)
    draw.text((4, 5), title, fill=(0, 0, 0), font=font(14))
    for c, (tile, label) in enumerate(tiles):
        x = c * (size + gap)
        draw.text((x + 4, head + 3), label, fill=(0, 0, 0), font=font())
        sheet.paste(Image.fromarray(tile), (x, head + LABEL_PX))
    buf = io.BytesIO()
    sheet.save(buf, format="PNG")
    return buf.getvalue()


def body_one(args, path: Path, name: str, body, protected, intrinsics, camera: str, say, regressor=None) -> dict:
    """Fit one depth image and write its set (module doc). ``body()`` gives the
    :class:`~lit3d.body_fit.model.Body` (called once the image is read and cut: a bad image fails
    before Anny loads); ``intrinsics(w, h, label)`` gives its camera, ``camera`` says where that
    came from, ``say(line)`` prints a note; ``regressor``: a loaded
    :class:`~lit3d.body_fit.regressor.Regressor` to start from (None: the mean body). Returns the summary."""
    t_all = time.perf_counter()
    depth, units = read_depth_info(path, args.depth_scale)
    h, w = depth.shape
    intr = intrinsics(w, h, str(path))
    mask = read_mask(find_mask(args.mask, path), depth.shape) if args.mask else None
    opts = Options(mask=mask, near=args.near, far=args.far, remove_plane=args.remove_plane,
                   largest_cluster=args.largest_cluster)
    keep, info = cut_object(depth, intr, opts, str(path))
    obs = observe(depth, intr, keep, str(path))
    body = body()
    t0, c0 = time.perf_counter(), time.process_time()
    fit = fit_body(body, obs) if regressor is None else \
        fit_from_regressor(body, regressor, obs, refine_config(poor_extra_iters=args.body_refine_poor))
    fit_cpu = time.process_time() - c0
    out = fit_outputs(body, fit, obs)
    timings = {"fit": fit.seconds, "fit_cpu": fit_cpu, "outputs": time.perf_counter() - t0 - fit.seconds}
    q = out.quality
    verdict = "POOR FIT: " + "; ".join(q["poor_fit_reasons"]) if q["poor_fit"] else "fit ok"
    files = {f".{args.format}": _mesh_bytes(out.posed, out.faces, args.format),
             f"_canonical.{args.format}": _mesh_bytes(out.canonical, out.faces, args.format),
             "_canonical_depth.npy": _npy_bytes(out.canonical_depth)}
    if not args.no_figure:
        t0 = time.perf_counter()
        title = (f"{path.name}: Anny fit to {len(obs.points)} points: median {100 * q['median_point_to_surface_m']:.1f} "
                 f"cm, silhouette IoU {q['silhouette_iou']:.2f} ({verdict})")
        files[".png"] = body_figure(obs.points, out, title, args.size)
        timings["figure"] = time.perf_counter() - t0
    timings["total"] = time.perf_counter() - t_all
    summary = {"input": str(path), "image_size": [w, h], "intrinsics": intr.as_dict(), "camera": camera,
               "depth_scale": units["depth_scale_applied"], "depth_units": units["units"],
               "mask": None if mask is None else str(args.mask), "counts": {**info, "points": len(obs.points),
                                                                            "loss_points": len(obs.sample)},
               "quality": q, "poor_fit": q["poor_fit"], "params": out.params, "timings_s": timings,
               "start": start_label(regressor),
               "mesh_frame": "NAME_body: camera (x right, y down, z forward), metres; NAME_body_canonical: "
                             "Anny rest pose, y up, facing +z, metres",
               "canonical_depth": "(128, 128) float32 in [0, 1], 0 = background: the canonical task's Anny "
                                  "targets (scale_mode=shape, view_mode=fixed, azimuth 0)",
               "output_name": name, "request": request_key(args, path)}
    if q["poor_fit"]:
        say(f"warning: {path}: {verdict} (probably not a person, or not cut from its background); "
            f"written with poor_fit: true")
    write_outputs(args.out, f"{name}_body", files, summary, protected)
    return summary
