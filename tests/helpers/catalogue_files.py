"""Tiny model files in the game catalogues' formats (AC3D .ac, Quake MD2) for the catalogue readers' tests."""
from __future__ import annotations

import struct

CUBE_QUADS = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]


TET_T = [(0, 1, 2), (0, 3, 1), (0, 2, 3), (1, 3, 2)]  # Quake-2 order: clockwise from outside


TET_V = [(0, 0, 0), (10, 0, 0), (0, 10, 0), (0, 0, 10)]


def ac_file(*objects: str, data: str = "") -> str:
    head = 'AC3Db\nMATERIAL "m" rgb 1 1 1  amb 0.2 0.2 0.2  emis 0 0 0  spec 0 0 0  shi 10  trans 0\n'
    return head + f"OBJECT world\n{data}kids {len(objects)}\n" + "\n".join(objects) + "\n"


def ac_object(name: str, verts, surfaces, kids: int = 0, extra: str = "", flags: str = "0x10") -> str:
    """One AC3D OBJECT block (surfaces: vertex index tuples, one SURF each)."""
    out = ["OBJECT poly", f'name "{name}"', *([extra] if extra else []), f"numvert {len(verts)}"]
    out += [" ".join(str(c) for c in v) for v in verts]
    out.append(f"numsurf {len(surfaces)}")
    for s in surfaces:
        out += [f"SURF {flags}", "mat 0", f"refs {len(s)}", *(f"{i} 0 0" for i in s)]
    out.append(f"kids {kids}")
    return "\n".join(out)


def md2_bytes(verts, tris, scale=(1.0, 1.0, 1.0), translate=(0.0, 0.0, 0.0), frames: int = 1) -> bytes:
    """A minimal MD2: no skins, no texture coordinates, ``frames`` identical frames."""
    nxyz, ntris = len(verts), len(tris)
    framesize = 40 + 4 * nxyz
    otris = 68
    oframes = otris + 12 * ntris
    oend = oframes + frames * framesize
    head = struct.pack("<4s16i", b"IDP2", 8, 64, 64, framesize, 0, nxyz, 0, ntris, 0, frames,
                       68, 68, otris, oframes, oend, oend)
    body = b"".join(struct.pack("<6H", *t, 0, 0, 0) for t in tris)
    frame = struct.pack("<6f16s", *scale, *translate, b"frame0")
    frame += b"".join(struct.pack("<4B", *v, 0) for v in verts)
    return head + body + frame * frames
