"""The files of one reconstruction, built in memory first and then written atomically.

For input ``NAME.*`` in ``out_dir``:

- ``NAME.obj|ply|glb``: the mesh, camera frame (x right, y down, z forward), metres;
- ``NAME_occupancy.npz``: ``bits`` (``np.packbits`` of the ``(R, R, R)`` bool grid, C order),
  ``shape``, ``threshold``, ``index_to_camera`` (``(4, 4)``: continuous grid index -> metres),
  readable by :func:`lit3d.render.convert.to_mesh` (and so by ``lit3d-score``);
- ``NAME.png``: the labelled picture (:mod:`lit3d.reconstruct.figure`);
- ``NAME.json``: the summary (timings per step, grid sizes, threshold, checkpoint, notes, score).

Nothing is written until every file's bytes exist, and each file is replaced atomically, so a
failure leaves no half-written output.
"""
from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np

from lit3d.reconstruct.pipeline import Result, index_to_camera_matrix
from lit3d.utils.io import atomic_write_bytes

MESH_FORMATS = ("obj", "ply", "glb")


def occupancy_npz(result: Result, threshold: float) -> bytes:
    """Packed-bit ``.npz`` bytes of the completed grid (see the module doc)."""
    buf = io.BytesIO()
    np.savez_compressed(buf, bits=np.packbits(result.occupancy.ravel()), shape=np.array(result.occupancy.shape),
                        threshold=np.float32(threshold), index_to_camera=index_to_camera_matrix(result.placement))
    return buf.getvalue()


def mesh_bytes(mesh, fmt: str) -> bytes:
    """The mesh exported as ``fmt`` (one of :data:`MESH_FORMATS`)."""
    data = mesh.export(file_type=fmt)
    return data.encode("utf-8") if isinstance(data, str) else bytes(data)


def write_outputs(out_dir: str | Path, name: str, files: dict[str, bytes], summary: dict) -> list[Path]:
    """Write ``files`` (suffix -> bytes) as ``out_dir/name<suffix>``, the JSON summary last."""
    out = Path(out_dir)
    blobs = dict(files)
    blobs[".json"] = (json.dumps(_plain(summary), indent=2, sort_keys=True) + "\n").encode("utf-8")
    return [atomic_write_bytes(out / f"{name}{suffix}", data) for suffix, data in blobs.items()]


def _plain(obj):
    """JSON-safe copy: numpy scalars/arrays to Python, NaN/inf to None."""
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _plain(obj.tolist())
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj
