"""Views, G-buffers, MatCap styles and representation conversion."""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch
import trimesh

from lit3d.render.convert import ShapeError, mesh_hash, normalise, to_mesh
from lit3d.render.dodecahedron import camera_poses, dodecahedron_directions


def test_dodecahedron_directions_unit_twelve_and_angles():
    d = dodecahedron_directions()
    assert d.shape == (12, 3)
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-15)
    dots = d @ d.T
    off = dots[~np.eye(12, dtype=bool)].reshape(12, 11)
    s5 = 1 / math.sqrt(5)
    for row in off:  # per direction: 5 at +1/sqrt5, 5 at -1/sqrt5, 1 antipode
        vals = np.sort(row)
        assert np.allclose(vals[:1], -1.0) and np.allclose(vals[1:6], -s5) and np.allclose(vals[6:], s5)
    angles = np.degrees(np.arccos(np.clip(off, -1, 1)))
    assert np.allclose(np.unique(np.round(angles, 6)), [63.434949, 116.565051, 180.0])
    # they are the face normals of a regular dodecahedron: the vertices of an icosahedron
    ico = trimesh.creation.icosahedron()
    v = ico.vertices / np.linalg.norm(ico.vertices, axis=1, keepdims=True)
    assert np.allclose(np.sort(np.abs(v @ d.T).max(0)), 1.0)


def test_camera_poses_look_at_origin():
    poses = camera_poses(3.0)
    d = dodecahedron_directions()
    for p, di in zip(poses, d):
        assert np.allclose(p[:3, :3] @ p[:3, :3].T, np.eye(3), atol=1e-12)
        assert np.allclose(p[:3, 3], 3.0 * di)
        assert np.allclose(-p[:3, 2], -di)  # camera looks down -z towards the origin


@pytest.fixture(scope="module")
def sphere_gb():
    from lit3d.render.gbuffer import RenderConfig, render_gbuffers

    return render_gbuffers(trimesh.creation.icosphere(4), RenderConfig(size=64))


def test_gbuffer_sphere_normals_match_image_position(sphere_gb):
    for shading in ("flat", "smooth"):
        gb = sphere_gb[shading]
        assert gb.normals.shape == (12, 3, 64, 64) and gb.mask.dtype == torch.bool
        # orthographic unit sphere scaled to a unit box (radius 0.5), extent 0.9:
        # the view-space normal at pixel (x, y) is ((x, y) / 0.5, nz)
        ys, xs = torch.meshgrid(torch.arange(64), torch.arange(64), indexing="ij")
        px = ((xs + 0.5) / 64 * 2 - 1) * 0.9 / 0.5
        py = -((ys + 0.5) / 64 * 2 - 1) * 0.9 / 0.5
        inner = gb.mask[:, 0] & (px**2 + py**2 < 0.8**2)
        err_x = (gb.normals[:, 0] - px)[inner].abs().mean()
        err_y = (gb.normals[:, 1] - py)[inner].abs().mean()
        assert err_x < 0.05 and err_y < 0.05, (shading, err_x, err_y)
        frac = gb.mask.float().mean().item()
        assert abs(frac - math.pi * (0.5 / 1.8) ** 2) < 0.02


def test_styles_registry_lut_matches_direct(sphere_gb):
    from lit3d.render.styles import STYLES, apply_styles, resolve_styles

    assert len(STYLES) == 30 and "ceramic_lightbulb" in STYLES
    gb = sphere_gb["smooth"]
    lut = apply_styles(gb.normals[:2], gb.mask[:2])
    direct = apply_styles(gb.normals[:2], gb.mask[:2], mode="direct")
    assert lut.shape == (30, 2, 3, 64, 64)
    assert (lut - direct).abs().mean() < 0.01
    assert float(lut.min()) >= 0 and float(lut.max()) <= 1
    assert (lut[:, :, :, ~gb.mask[0, 0]] == 0).all()
    # styles differ from each other
    flat = lut.flatten(1)
    d = torch.cdist(flat, flat)
    assert (d + torch.eye(30) * 1e9).min() > 0.5
    assert resolve_styles("toon, jade") == ["toon", "jade"]
    with pytest.raises(ValueError, match="unknown style"):
        resolve_styles("nope")


def test_to_mesh_formats(tmp_path):
    sph = trimesh.creation.icosphere(3)
    for ext in ("obj", "off", "ply", "stl", "glb"):
        p = tmp_path / f"s.{ext}"
        sph.export(p)
        m = to_mesh(p)
        assert len(m.faces) == len(sph.faces), ext
    x, y, z = np.mgrid[-1:1:32j, -1:1:32j, -1:1:32j]
    sdf = np.sqrt(x**2 + y**2 + z**2) - 0.6
    np.savez(tmp_path / "sdf.npz", sdf=sdf)
    np.savez(tmp_path / "vox.npz", arr_0=(sdf < 0).astype(np.int8)[..., None])
    np.savez(tmp_path / "bits.npz", bits=np.packbits(sdf < 0), shape=np.array(sdf.shape))
    for name in ("sdf.npz", "vox.npz", "bits.npz"):
        m = to_mesh(tmp_path / name)
        assert m.volume > 0 and abs(np.ptp(m.vertices, 0) - np.ptp(m.vertices, 0)[0]).max() < 1.5
    pts = sph.sample(5000, seed=0) if "seed" in trimesh.sample.sample_surface.__code__.co_varnames else sph.sample(5000)
    np.savetxt(tmp_path / "p.xyz", pts)
    m = to_mesh(tmp_path / "p.xyz")
    assert m.volume > 0
    assert mesh_hash(normalise(sph)) == mesh_hash(normalise(sph.copy()))


@pytest.mark.parametrize("content,msg", [
    (b"", "empty file"),
    (bytes(range(256)) * 8, "s.obj"),
    (b"v 0 0 0\nv 1 0 0\nv 0 1 0\n", "no faces"),
    (b"v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n", "NaN"),
    (b"v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n", "degenerate"),
])
def test_to_mesh_errors_name_the_file(tmp_path, content, msg):
    p = tmp_path / "s.obj"
    p.write_bytes(content)
    with pytest.raises(ShapeError) as e:
        to_mesh(p)
    assert str(p) in str(e.value) and msg in str(e.value) and "\n" not in str(e.value)


def test_to_mesh_directory_and_missing(tmp_path):
    with pytest.raises(ShapeError, match="a folder, not a file"):
        to_mesh(tmp_path)
    with pytest.raises(ShapeError, match="no such file"):
        to_mesh(tmp_path / "nope.obj")
    np.savez(tmp_path / "e.npz", arr_0=np.zeros((8, 8, 8)))
    with pytest.raises(ShapeError, match="empty"):
        to_mesh(tmp_path / "e.npz")
