"""Quake-2 models (``.md2``) read into triangle meshes: frame 0 of the animation.

trimesh reads no ``.md2``, so this is a reader of its own, written from the format's public
description (id Software's ``qfiles.h``) and checked on the models of the Debian package
``ufoai-data`` (``base/0models.pk3``, a zip). A file is little-endian binary:

- a 68-byte header of 17 int32: ``ident`` (``b"IDP2"``), ``version`` (8), skin width and height,
  ``framesize`` (bytes per frame), the counts of skins, vertices, texture coordinates, triangles,
  GL commands and frames, and the byte offsets of skins, texture coordinates, triangles,
  frames, GL commands and the end of the file;
- ``num_tris`` triangles of 12 bytes: three uint16 vertex indices and three texture indices;
- ``num_frames`` frames of ``framesize`` bytes: float32 ``scale[3]``, float32 ``translate[3]``, a
  16-byte name, then ``num_xyz`` packed vertices of 4 bytes (uint8 x, y, z and a normal index);
  a vertex is ``packed * scale + translate``.

Only frame 0 is read (the rest pose of UFO:AI's props and weapons). Quake-2 triangles are
clockwise seen from outside; they are returned counter-clockwise (outward normals). Axes are the
file's (Quake: z up). A bad file raises :class:`~datamodules.cache.DataError` naming the file and
the problem (wrong magic or version, counts or offsets outside the file, vertex index out of range).
"""
from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from datamodules.cache import DataError
from datamodules.completion.archives import source_bytes

MAGIC, VERSION = b"IDP2", 8
HEADER = struct.Struct("<4s16i")
MAX_VERTS, MAX_TRIS = 65536, 1 << 20  # far above Quake 2's limits (2048, 4096); only a sanity bound
FRAME_HEAD = 40  # scale (3 float32), translate (3 float32), name (16 bytes)


def read_md2_arrays(data: bytes, where: str = "<bytes>") -> tuple[np.ndarray, np.ndarray]:
    """Frame 0 of an MD2 file's bytes -> (V, 3) float64 vertices, (F, 3) int64 faces (counter-clockwise).

    Raises:
        DataError: naming ``where`` and the problem.
    """
    if len(data) < HEADER.size:
        raise DataError(f"{where}: truncated MD2: {len(data)} bytes, shorter than its {HEADER.size}-byte header")
    (ident, version, _sw, _sh, framesize, _nskins, nxyz, _nst, ntris, _ngl, nframes,
     _oskins, _ost, otris, oframes, _ogl, oend) = HEADER.unpack_from(data)
    if ident != MAGIC:
        raise DataError(f"{where}: not an MD2 file (magic {ident!r}, expected {MAGIC!r})")
    if version != VERSION:
        raise DataError(f"{where}: MD2 version {version}, expected {VERSION}")
    if not (0 < nxyz <= MAX_VERTS and 0 < ntris <= MAX_TRIS and nframes > 0):
        raise DataError(f"{where}: bad MD2 counts: {nxyz} vertices, {ntris} triangles, {nframes} frames")
    if framesize < FRAME_HEAD + 4 * nxyz:
        raise DataError(f"{where}: MD2 frame size {framesize} too small for {nxyz} vertices")
    for what, start, size in (("triangles", otris, 12 * ntris), ("frame 0", oframes, framesize)):
        if start < HEADER.size or start + size > len(data):
            raise DataError(f"{where}: truncated MD2: {what} at bytes {start}..{start + size} "
                            f"but the file has {len(data)} bytes (header says it ends at {oend})")
    tris = np.frombuffer(data, "<u2", count=6 * ntris, offset=otris).reshape(ntris, 6)[:, :3].astype(np.int64)
    if tris.max() >= nxyz:
        raise DataError(f"{where}: MD2 triangle uses vertex {int(tris.max())} of {nxyz}")
    scale = np.frombuffer(data, "<f4", count=3, offset=oframes).astype(np.float64)
    translate = np.frombuffer(data, "<f4", count=3, offset=oframes + 12).astype(np.float64)
    if not (np.isfinite(scale).all() and np.isfinite(translate).all()):
        raise DataError(f"{where}: MD2 frame 0 has a non-finite scale or translation")
    packed = np.frombuffer(data, np.uint8, count=4 * nxyz, offset=oframes + FRAME_HEAD).reshape(nxyz, 4)[:, :3]
    vertices = packed.astype(np.float64) * scale + translate
    return vertices, tris[:, ::-1].copy()


def read_md2(source: str | Path | bytes, where: str | None = None):
    """An MD2 file (path, ``archive::member`` inside a zip/pk3, or bytes) as a ``trimesh.Trimesh`` (frame 0).

    Raises:
        DataError: unreadable, truncated or garbled file (the message names it).
    """
    import trimesh

    data, where = source_bytes(source, where)
    return trimesh.Trimesh(*read_md2_arrays(data, where), process=False)
