"""The files of one reconstruction, built in memory first and then written atomically.

For input ``NAME.*`` in ``out_dir``:

- ``NAME.obj|ply|glb``: the mesh, camera frame (x right, y down, z forward), metres;
- ``NAME_occupancy.npz``: ``bits`` (``np.packbits`` of the ``(R, R, R)`` bool grid, C order),
  ``shape``, ``threshold``, ``index_to_camera`` (``(4, 4)``: continuous grid index -> metres),
  readable by :func:`lit3d.render.convert.to_mesh` (and so by ``lit3d-score``);
- ``NAME.png``: the labelled picture (:mod:`lit3d.reconstruct.figure`);
- ``NAME.json``: the summary (timings per step, grid sizes, threshold, checkpoint, notes, score).

Nothing is written until every file's bytes exist; the set is written into a temp folder inside
``out_dir`` and renamed into place only when complete (:func:`lit3d.utils.io.write_file_set`),
so a failure leaves no half-written output and no part of a set; a set a killed run left half
renamed is finished by the next run (:func:`lit3d.utils.io.repair_sets`). An output that would
replace an input file, or that exists as a folder, is refused before anything is written.
The JSON records a ``request`` key (:func:`request_key`: the input, the files read and every
option); a rerun skips the inputs whose set is whole with the same key
(:func:`finished_set`), unless ``--overwrite``.
"""
from __future__ import annotations

import hashlib
import io
import json
from pathlib import Path

import numpy as np

from lit3d.reconstruct.depth_io import InputError, find_mask
from lit3d.reconstruct.pipeline import Result, index_to_camera_matrix
from lit3d.utils.io import write_file_set

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


OUTPUT_SUFFIXES = ("_occupancy.npz", ".png", ".json")  # besides the mesh's ".<format>"


def output_files(name: str, fmt: str, figure: bool = True) -> list[str]:
    """The file names one input ``name`` gives (see the module doc)."""
    return [f"{name}.{fmt}", f"{name}_occupancy.npz"] + ([f"{name}.png"] if figure else []) + [f"{name}.json"]


REQUEST_FILES = ("ckpt", "canonical", "reference", "quality_ckpt", "mask", "body_init")  # options naming files the run reads
REQUEST_IGNORED = ("depth", "out", "debug", "device", "overwrite")  # options that do not change a set


def _stamp(path) -> list | None:
    if not path:
        return None
    p = Path(path)
    try:
        st = p.stat()
    except OSError:
        return [str(p), None, None]
    return [str(p.resolve()), st.st_size, st.st_mtime_ns]


def _mask_file(mask, path: Path):
    """The mask file input ``path`` is cut with (``--mask`` itself, or its file in a mask folder);
    the folder where it has none (that input then fails with its own line)."""
    try:
        return find_mask(mask, path) if mask else None
    except InputError:
        return mask


def request_key(args, path: Path) -> str:
    """sha256 of what decides the set of input ``path``: the input file and every file the run
    reads (path, size, mtime; of a mask folder, the mask of this input) and every option of the
    command line ``args`` (an argparse Namespace) but the output folder, the device and the
    switches of this kind."""
    options = {k: v for k, v in sorted(vars(args).items()) if k not in REQUEST_IGNORED and k not in REQUEST_FILES}
    files = {k: _stamp(getattr(args, k, None)) for k in REQUEST_FILES}
    files["mask"] = _stamp(_mask_file(getattr(args, "mask", None), path))
    text = json.dumps({"input": _stamp(path), "files": files, "options": options}, sort_keys=True, default=str)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def finished_set(out_dir: str | Path, name: str, fmt: str, figure: bool, key: str) -> bool:
    """True when every file of ``name``'s set is in ``out_dir`` and its JSON records ``key``."""
    out = Path(out_dir)
    if not all((out / f).is_file() for f in output_files(name, fmt, figure)):
        return False
    try:
        return json.loads((out / f"{name}.json").read_text("utf-8")).get("request") == key
    except (OSError, ValueError, AttributeError):
        return False


def write_outputs(out_dir: str | Path, name: str, files: dict[str, bytes], summary: dict,
                  protected=()) -> list[Path]:
    """Write ``files`` (suffix -> bytes) as ``out_dir/name<suffix>`` as one set, the JSON summary
    last; ``protected``: input files no output may replace."""
    blobs = {f"{name}{suffix}": data for suffix, data in files.items()}
    blobs[f"{name}.json"] = (json.dumps(_plain(summary), indent=2, sort_keys=True) + "\n").encode("utf-8")
    return write_file_set(out_dir, blobs, protected)


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
