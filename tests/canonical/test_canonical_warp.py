"""The warp head and its flow targets: zero flow gives the input, the true flow gives the canonical
silhouette, a known rigid motion gives its flow, occluded surface is not visible, mirrored pairs keep
their flow, and the head learns a flow it is shown."""
import numpy as np
import pytest
import torch
import trimesh
from scipy.ndimage import binary_erosion
from omegaconf import OmegaConf

from datamodules.canonical import CanonicalDataModule
from datamodules.canonical.flow import flow_targets
from datamodules.canonical.rendering import PairRenderer
from datamodules.canonical.settings import RenderSettings
from datamodules.canonical.sources import AnnySource, SynthSource
from lit3d.canonical.factory import build_canonical_net
from lit3d.canonical.nets import UNetTrunk
from lit3d.canonical.losses import flow_loss
from lit3d.canonical.warp import WarpHead, pixels_to_grid, warp_compose, warp_image
from lit3d.render.depth import render_depth

SIZE = 96
RENDER = RenderSettings(azimuths=(0.0,), view_mode="fixed", scale_mode="shape", flow_targets=True)


def _t(a) -> torch.Tensor:
    return torch.as_tensor(np.asarray(a, np.float32))[None, None]


def _unpack(packed, size):
    return np.unpackbits(packed)[: size * size].reshape(size, size).astype(bool)


def _warped_mask(posed_mask, flow_px) -> np.ndarray:
    """The posed mask moved by a flow in pixels ``(2, S, S)``, bilinear, at 0.5."""
    grid = pixels_to_grid(torch.as_tensor(np.asarray(flow_px, np.float32))[None])
    return (warp_image(_t(posed_mask), grid)[0, 0] > 0.5).numpy()


def _iou_on(a: np.ndarray, b: np.ndarray, where: np.ndarray) -> float:
    a, b = a & where, b & where
    return float((a & b).sum() / max((a | b).sum(), 1))


def test_zero_flow_reproduces_the_posed_input_exactly():
    g = torch.Generator().manual_seed(0)
    depth = torch.rand(2, 1, 40, 56, generator=g)
    mask = (torch.rand(2, 1, 40, 56, generator=g) > 0.4).float()
    zero = torch.zeros(2, 1, 40, 56)
    coeffs = torch.zeros(2, 4, 40, 56)
    d, m = warp_compose(depth, mask, torch.zeros(2, 2, 40, 56), coeffs, torch.ones_like(zero), zero, zero)
    # exact to float32 precision (grid_sample maps the pixel centres back with an error of about 2e-6)
    assert torch.allclose(d, depth, atol=1e-5, rtol=0) and torch.allclose(m, mask, atol=1e-5, rtol=0)
    # a one-pixel flow moves the image by one pixel (the composition really samples the flow)
    one = pixels_to_grid(torch.tensor([1.0, 0.0]).view(1, 2, 1, 1).expand(2, 2, 40, 56))
    d1, _ = warp_compose(depth, mask, one, coeffs, torch.ones_like(zero), zero, zero)
    assert torch.allclose(d1[..., :-1], depth[..., 1:], atol=1e-5)


@pytest.mark.parametrize("reconstruction", ["downup", "unet"])
def test_untrained_warp_net_returns_its_input(compose_cfg, reconstruction):
    net_cfg = OmegaConf.to_container(compose_cfg(["experiment=canonical_tiny", "task.net.head.kind=warp",
                                                  f"task.net.reconstruction.kind={reconstruction}"]).task.net, resolve=True)
    net = build_canonical_net({"kind": "canonical", **net_cfg})
    assert isinstance(net.head, WarpHead)
    assert isinstance(net.reconstruction, UNetTrunk) == (reconstruction == "unet")
    depth = torch.rand(2, 1, 48, 48)
    mask = (depth > 0.5).float()
    depth = depth * mask
    out = net(depth, mask)
    assert out.flow.abs().max() == 0 and out.flow.shape == (2, 2, 48, 48)
    assert (out.depth - depth).abs().max() < 0.02 and (out.mask - mask).abs().max() < 0.02


def _box(centre, extents, subdiv=4):
    m = trimesh.creation.box(extents=extents)
    for _ in range(subdiv):
        m = m.subdivide()
    return m.vertices + np.asarray(centre), m.faces


def test_rigid_motion_gives_its_flow_and_full_visibility():
    size = 64
    v, f = _box((0.0, 0.0, 0.0), (0.5, 0.6, 0.3))
    shift = np.array([0.11, -0.055, 0.0])  # world units: 0.55 = half the image -> 32 px per 0.55
    d0, m0 = render_depth(v, f, size)
    d1, m1 = render_depth(v + shift, f, size)
    flow, vis = flow_targets(v, v + shift, d0, m0, d1, m1)
    px = shift[:2] / 0.55 * size / 2 * np.array([1, -1])  # image y runs down
    inside = m0 & vis
    assert inside.sum() > 0.95 * m0.sum()
    assert np.allclose(flow[0][inside], px[0], atol=0.3) and np.allclose(flow[1][inside], px[1], atol=0.3)
    assert _iou_on(_warped_mask(m1, flow), m0, vis) > 0.99


def test_affine_depth_model_gives_a_rotated_part_its_canonical_depth():
    """A box turned 25 degrees further about the vertical (canonical 10, posed 35 degrees: no face is
    flat to the camera): moved by its true flow, its posed depth becomes its
    canonical depth under the affine model (``c0 + c1 x + c2 y + (1 + c3) D``, constant coefficients
    for a rigid part, fitted by least squares) to within the renderer's pixel error, which an offset
    alone cannot do."""
    size = 96
    v, f = _box((0.0, 0.0, 0.0), (0.5, 0.6, 0.25))

    def turned(deg):
        a = np.radians(deg)
        return v @ np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]]).T

    v, posed = turned(10.0), turned(35.0)
    dc, mc = render_depth(v, f, size)
    dp, mp = render_depth(posed, f, size)
    flow_px, vis = flow_targets(v, posed, dc, mc, dp, mp)
    flow = pixels_to_grid(torch.as_tensor(flow_px, dtype=torch.float32)[None])
    zero, one = torch.zeros(1, 1, size, size), torch.ones(1, 1, size, size)
    moved, _ = warp_compose(_t(dp), _t(mp), flow, torch.zeros(1, 4, size, size), one, zero, zero)
    src = (torch.stack(torch.meshgrid((torch.arange(size) + 0.5) / size * 2 - 1, (torch.arange(size) + 0.5)
                                      / size * 2 - 1, indexing="ij")[::-1])[None] + flow)[0].numpy()
    # away from the silhouette's edge, where bilinear sampling mixes in the background
    inner = vis & mc & _warped_mask(binary_erosion(mp, iterations=2), flow_px)
    dm = moved[0, 0].numpy()[inner]
    fit = np.stack([np.ones_like(dm), src[0][inner], src[1][inner], dm], 1)
    c, *_ = np.linalg.lstsq(fit, dc[inner] - dm, rcond=None)
    coeffs = torch.tensor(c, dtype=torch.float32).view(1, 4, 1, 1).expand(1, 4, size, size)
    affine, _ = warp_compose(_t(dp), _t(mp), flow, coeffs, one, zero, zero)
    err_affine = np.abs(affine[0, 0].numpy()[inner] - dc[inner])
    err_offset = np.abs(dm + np.median(dc[inner] - dm) - dc[inner])
    assert inner.sum() > 0.5 * mc.sum()
    assert np.median(err_affine) < 0.1 * np.median(err_offset) and np.percentile(err_affine, 95) < 0.01


def test_occluded_surface_is_not_visible():
    size = 64
    big_v, big_f = _box((0.15, 0.0, 0.0), (0.3, 0.6, 0.2))
    small_v, small_f = _box((-0.25, 0.0, 0.0), (0.2, 0.3, 0.2))
    verts = np.concatenate([big_v, small_v])
    faces = np.concatenate([big_f, small_f + len(big_v)])
    moved = np.concatenate([big_v, small_v + np.array([0.4, 0.0, 0.25])])  # small box now in front of the big one
    d0, m0 = render_depth(verts, faces, size)
    d1, m1 = render_depth(moved, faces, size)
    flow, vis = flow_targets(verts, moved, d0, m0, d1, m1)
    cols = np.arange(size)
    x = (cols + 0.5) / size * 2 * 0.55 - 0.55
    big_cols = (x > 0.06) & (x < 0.24)  # behind the small box in the posed view (rows |y| < 0.15)
    small_cols = x < -0.2
    y = -x  # the same pixel grid for rows (row 0 = top)
    hidden = m0 & big_cols[None, :] & (np.abs(y) < 0.12)[:, None]
    shown = m0 & big_cols[None, :] & (np.abs(y) > 0.18)[:, None]
    assert vis[hidden].mean() < 0.1 and vis[shown].mean() > 0.9
    assert vis[:, small_cols][m0[:, small_cols]].mean() > 0.9


@pytest.mark.parametrize("source", ["synth", "anny"])
def test_true_flows_reproduce_the_canonical_mask(source):
    src = (SynthSource(["humanoid", "quadruped"], 2, 3, 0, 40, 0, 15.0, 1.0) if source == "synth"
           else AnnySource(1, 3, 0, 0, 15.0, 1.0))
    size = SIZE
    for subject in src.subjects():
        arrays = PairRenderer(src, RENDER, SIZE).render_subject(subject)
        canon = _unpack(arrays["mask_canonical_0"], size)
        for p in arrays["poses"]:
            flow = arrays[f"flow_{p}_0"].astype(np.float32)
            vis = _unpack(arrays[f"vis_{p}_0"], size)
            posed = _unpack(arrays[f"mask_{p}_0"], size)
            assert vis.sum() > 0.6 * canon.sum() and not (vis & ~canon).any()
            assert _iou_on(_warped_mask(posed, flow), canon, vis) >= 0.95
            # the posed mask left in place is a poorer canonical form: the flow carries the pose change
            assert _iou_on(posed, canon, canon) < _iou_on(_warped_mask(posed, flow), canon, canon)


def test_mirrored_pairs_keep_a_true_flow(tmp_path):
    dm = CanonicalDataModule.from_flat(str(tmp_path / "data"), image_size=48, n_subjects=3, n_poses=3, mesh_resolution=28,
                             n_folds=3, batch_size=4, kinds=["humanoid"], seed=1, split="all", flow_targets=True,
                             flip_lr=False)
    dm.prepare_data()
    dm.setup()
    ds = dm.datasets["test"]
    assert "flow_targets" in dm.cache_config()
    ds.flip_lr = True
    torch.manual_seed(0)
    seen = {True: 0, False: 0}
    for i in range(len(ds)):
        it = ds[i]
        if not it["has_flow"]:
            continue
        flipped = not torch.equal(it["depth"][0], torch.from_numpy(dm.cache[it["subject"]]["depth"][f"{it['pose']}_0"]))
        seen[flipped] += 1
        vis = it["vis"][0].numpy() > 0.5
        warped = _warped_mask(it["mask"][0].numpy() > 0.5, it["flow"].numpy())
        assert _iou_on(warped, it["canon_mask"][0].numpy() > 0.5, vis) >= 0.95
    assert seen[True] and seen[False]
    batch = next(iter(dm.test_dataloader()))
    assert batch["flow"].shape == (4, 2, 48, 48) and batch["has_flow"].dtype == torch.bool


def test_cache_without_flows_keeps_its_config(tmp_path):
    dm = CanonicalDataModule.from_flat(str(tmp_path / "d"), image_size=32, n_subjects=3, n_poses=3, mesh_resolution=24)
    assert "flow_targets" not in dm.cache_config()
    # a flow cache hashes the flow's version alone, as the caches written since the flows came (the removed
    # forward flow of the splat head added "+forward" to it, only when it was on)
    flows = CanonicalDataModule.from_flat(str(tmp_path / "f"), image_size=32, n_subjects=3, n_poses=3, mesh_resolution=24,
                                          flow_targets=True).cache_config()["flow_targets"]
    assert flows == "flow-1"


def test_warp_head_learns_a_flow_it_is_shown():
    """A broken head (flow not reaching the output, or not trainable) would stay at its start."""
    torch.manual_seed(0)
    size, shift = 32, 5.0
    head = WarpHead(3, hidden=16)
    opt = torch.optim.Adam(head.parameters(), lr=3e-3)
    target = torch.zeros(4, 2, size, size)
    target[:, 0] = shift
    vis = torch.ones(4, 1, size, size)
    has = torch.ones(4, dtype=torch.bool)
    start = None
    for _ in range(150):
        depth = torch.rand(4, 1, size, size)
        mask = (depth > 0.3).float()
        out = head(torch.cat([depth, mask, torch.ones_like(depth)], 1), depth, mask)
        loss = flow_loss(out.flow, pixels_to_grid(target), vis, has)
        start = float(loss.detach()) if start is None else start
        opt.zero_grad()
        loss.backward()
        opt.step()
    epe_px = float(loss.detach()) * size / 2
    assert start * size / 2 == pytest.approx(shift, abs=0.01) and epe_px < 0.5


def test_warp_oracle_is_the_truth_where_seen_and_the_mean_body_elsewhere():
    from lit3d.canonical.pooled import warp_oracle

    rng = np.random.default_rng(0)
    mask = (rng.random((6, 1, 16, 16)) > 0.3).astype(np.float32)
    depth = rng.random((6, 1, 16, 16)).astype(np.float32) * mask
    seen = {"canon_depth": depth, "canon_mask": mask, "vis": np.ones_like(mask)}  # every pixel seen: the truth
    d, m = warp_oracle(seen)
    np.testing.assert_allclose(d, depth)
    np.testing.assert_array_equal(m, mask)
    d0, m0 = warp_oracle({**seen, "vis": np.zeros_like(mask)})
    mean_mask = (mask.mean(0) >= 0.5).astype(np.float32)
    assert (m0 == mean_mask[None]).all() and np.allclose(d0[0], d0[5])  # one mean body for every item
    inside = mean_mask[0] > 0
    expected = (depth * mask).sum(0)[0] / np.maximum(mask.sum(0)[0], 1)
    np.testing.assert_allclose(d0[0, 0][inside], expected[inside], rtol=1e-6)
