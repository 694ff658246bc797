"""The point-cloud metrics library (lit3d.metrics.clouds, lit3d.metrics.nearest) against independent
references: brute-force numpy, SciPy's cKDTree, PyTorch3D's formulas written out here, and hand cases.
On the GPU too when one is there."""
from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.spatial import cKDTree

from lit3d.metrics.clouds import bbox_diagonal, chamfer_distance, f_score, normal_consistency
from lit3d.metrics.nearest import nearest
from lit3d.metrics.surface import sample_grids, surface_scores

pytestmark = pytest.mark.usefixtures("one_torch_thread")

DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])


def clouds(b=3, n=70, m=50, seed=0):
    g = torch.Generator().manual_seed(seed)
    x = torch.rand(b, n, 3, generator=g, dtype=torch.float64)
    y = 0.8 * torch.rand(b, m, 3, generator=g, dtype=torch.float64) + 0.1
    nx, ny = torch.randn(b, n, 3, generator=g, dtype=torch.float64), torch.randn(b, m, 3, generator=g, dtype=torch.float64)
    return x, y, nx / nx.norm(dim=-1, keepdim=True), ny / ny.norm(dim=-1, keepdim=True)


def brute(x: np.ndarray, y: np.ndarray):
    """numpy: all pairwise distances ``(N, M)`` of one row, then the nearest both ways."""
    d = np.sqrt(((x[:, None, :] - y[None, :, :]) ** 2).sum(-1))
    return d.min(1), d.argmin(1), d.min(0), d.argmin(0)


def reference(x, y, nx, ny, tau):
    """Per-row reference values (numpy) of one unpadded row: l1, pytorch3d, F at tau, normal consistency."""
    d_xy, i_xy, d_yx, i_yx = brute(x, y)
    p, r = (d_xy <= tau).mean(), (d_yx <= tau).mean()
    f = 2 * p * r / (p + r) if p + r > 0 else 0.0
    nc = 0.5 * (np.abs((nx * ny[i_xy]).sum(1)).mean() + np.abs((ny * nx[i_yx]).sum(1)).mean())
    return 0.5 * (d_xy.mean() + d_yx.mean()), (d_xy**2).mean() + (d_yx**2).mean(), f, nc


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("backend", ["cdist", "kdtree"])
def test_matches_brute_force_ragged(device, backend):
    if device == "cuda" and backend == "kdtree":
        pytest.skip("the KD-tree backend is the CPU's")
    x, y, nx, ny = clouds()
    xl, yl = torch.tensor([70, 31, 5]), torch.tensor([50, 50, 12])
    kw = dict(x_lengths=xl.to(device), y_lengths=yl.to(device), reduction="none", backend=backend)
    xd, yd, nxd, nyd = (t.to(device) for t in (x, y, nx, ny))
    l1 = chamfer_distance(xd, yd, convention="l1", **kw).cpu()
    p3 = chamfer_distance(xd, yd, convention="pytorch3d", **kw).cpu()
    f = f_score(xd, yd, [0.05, 0.1], threshold_mode="absolute", **kw).cpu()
    nc = normal_consistency(xd, nxd, yd, nyd, **kw).cpu()
    for row in range(3):
        n, m = int(xl[row]), int(yl[row])
        a, b, na, nb = x[row, :n].numpy(), y[row, :m].numpy(), nx[row, :n].numpy(), ny[row, :m].numpy()
        for j, tau in enumerate((0.05, 0.1)):
            ref = reference(a, b, na, nb, tau)
            assert float(f[row, j]) == pytest.approx(ref[2], abs=1e-12)
        assert float(l1[row]) == pytest.approx(ref[0], rel=1e-12)
        assert float(p3[row]) == pytest.approx(ref[1], rel=1e-12)
        assert float(nc[row]) == pytest.approx(ref[3], rel=1e-12)
    assert 0 < float(f[:, 0].mean()) < 1  # the clouds differ: a real test of the thresholds


def test_chunked_cdist_equals_kdtree_on_larger_clouds():
    g = torch.Generator().manual_seed(1)
    x, y = torch.rand(2, 1500, 3, generator=g), torch.rand(2, 1200, 3, generator=g)
    chunked = nearest(x, y, backend="cdist", max_pairs=5000)  # 2 rows of x at a time
    tree = nearest(x, y, backend="kdtree")
    for row in range(2):
        d, i = cKDTree(y[row].double().numpy()).query(x[row].double().numpy())
        np.testing.assert_allclose(chunked.distance[row].numpy(), d, rtol=1e-6)
        assert (chunked.index[row].numpy() == i).mean() > 0.999  # float32 near-ties may pick the other one
        np.testing.assert_array_equal(tree.index[row].numpy(), i)


def test_hand_cases_identical_shifted_symmetric():
    grid = torch.stack(torch.meshgrid(*[torch.arange(4.0, dtype=torch.float64)] * 3, indexing="ij"), -1).reshape(1, -1, 3)
    assert float(chamfer_distance(grid, grid)) == 0.0
    assert float(f_score(grid, grid, 1e-9)) == 1.0
    normals = torch.randn_like(grid)
    assert float(normal_consistency(grid, normals, grid, normals)) == pytest.approx(1.0, abs=1e-12)
    d = 0.1  # points 1 apart, moved by 0.1: each one's nearest is its own moved copy
    moved = grid + torch.tensor([0.0, d, 0.0], dtype=torch.float64)
    assert float(chamfer_distance(grid, moved)) == pytest.approx(d, rel=1e-12)  # l1: mean d, halved sum
    assert float(chamfer_distance(grid, moved, convention="pytorch3d")) == pytest.approx(2 * d * d, rel=1e-12)
    assert float(chamfer_distance(grid, moved, squared=True, directions="mean")) == pytest.approx(d * d, rel=1e-12)
    assert float(f_score(grid, moved, 0.099)) == 0.0 and float(f_score(grid, moved, 0.101)) == 1.0
    x, y, nx, ny = clouds(seed=2)
    for conv in ("l1", "pytorch3d"):
        torch.testing.assert_close(chamfer_distance(x, y, convention=conv, reduction="none"),
                                   chamfer_distance(y, x, convention=conv, reduction="none"), rtol=1e-14, atol=0)
    torch.testing.assert_close(f_score(x, y, 0.07, reduction="none"), f_score(y, x, 0.07, reduction="none"))
    torch.testing.assert_close(normal_consistency(x, nx, y, ny, reduction="none"),
                               normal_consistency(y, ny, x, nx, reduction="none"))


def test_pytorch3d_formulas_written_out():
    """pytorch3d.loss.chamfer_distance(x, y, x_normals, y_normals) with its defaults (point_reduction and
    batch_reduction "mean", abs_cosine=True), written out from its definition:
    cham_x = sum_i min_j |x_i - y_j|^2 / N, cham_y likewise, loss = mean_b (cham_x + cham_y);
    normals loss = mean_b ((1 - mean_i |cos(n_i, n_nn(i))|) + (1 - mean_j |cos|))."""
    x, y, nx, ny = clouds(seed=3)
    d2 = ((x[:, :, None, :] - y[:, None, :, :]) ** 2).sum(-1)  # (B, N, M)
    loss = (d2.min(2).values.mean(1) + d2.min(1).values.mean(1)).mean()
    cos_x = torch.nn.functional.cosine_similarity(nx, torch.gather(ny, 1, d2.argmin(2)[..., None].expand(-1, -1, 3)), dim=-1)
    cos_y = torch.nn.functional.cosine_similarity(ny, torch.gather(nx, 1, d2.argmin(1)[..., None].expand(-1, -1, 3)), dim=-1)
    normals_loss = ((1 - cos_x.abs().mean(1)) + (1 - cos_y.abs().mean(1))).mean()
    assert float(chamfer_distance(x, y, convention="pytorch3d")) == pytest.approx(float(loss), rel=1e-12)
    # our normal consistency is PyTorch3D's normals loss turned round: NC = 1 - loss / 2
    assert float(normal_consistency(x, nx, y, ny)) == pytest.approx(1 - float(normals_loss) / 2, rel=1e-12)


def test_the_two_chamfer_and_fscore_conventions_on_completion_surfaces():
    """The same points give lit3d's Chamfer-L1 and a different PyTorch3D value; F@1% of the target's
    bounding-box diagonal (lit3d's tables) and of the volume side (Tatarchenko et al.) differ too."""
    grids = np.zeros((2, 24, 24, 24), bool)
    grids[0, 4:20, 4:20, 6:18] = True  # target: a box
    grids[1, 5:21, 4:19, 6:17] = True  # prediction: the box moved and shrunk by a voxel
    target, pred = sample_grids(grids, 3000, 0)
    ours = surface_scores(pred, target, [0.01])
    x, y = torch.from_numpy(pred.points)[None], torch.from_numpy(target.points)[None]
    l1 = float(chamfer_distance(x, y))
    p3 = float(chamfer_distance(x, y, convention="pytorch3d"))
    assert l1 == pytest.approx(ours["chamfer_l1"], rel=1e-12)  # the grid metrics are this library's "l1"
    d_xy, _, d_yx, _ = brute(pred.points, target.points)
    assert p3 == pytest.approx((d_xy**2).mean() + (d_yx**2).mean(), rel=1e-12)
    assert p3 < l1 / 2  # distances well below 1: squared values are far smaller; neither reads as the other
    # F@1%: lit3d's tables take 1% of the target mesh's bounding-box diagonal ...
    f_diag = float(f_score(x, y, 0.01 * target.diagonal))
    assert f_diag == pytest.approx(float(ours["fscore"][0]), abs=1e-12)
    # ... about what threshold_mode="bbox_diagonal" gives on the samples' own box
    assert float(bbox_diagonal(y)) == pytest.approx(target.diagonal, rel=0.02)
    # Tatarchenko et al.: 1% of the volume's side, which is 1 in lit3d's unit frame
    f_side = float(f_score(x, y, 0.01, threshold_mode="volume_side", side=1.0))
    assert f_side == float(f_score(x, y, 0.01, threshold_mode="absolute"))
    assert target.diagonal > 1 and f_diag > f_side  # a larger threshold: a higher F-score from the same points


def test_bbox_diagonal_threshold_mode_per_row():
    x, y, _, _ = clouds(seed=4)
    yl = torch.tensor([50, 20, 9])
    got = f_score(x, y, 0.1, threshold_mode="bbox_diagonal", y_lengths=yl, reduction="none")
    for row in range(3):
        b = y[row, :int(yl[row])].numpy()
        tau = 0.1 * np.linalg.norm(b.max(0) - b.min(0))
        assert float(got[row]) == pytest.approx(reference(x[row].numpy(), b, x[row].numpy(), b, tau)[2], abs=1e-12)


def test_chamfer_is_differentiable_and_batch_reductions():
    x, y, _, _ = clouds(seed=5)
    x.requires_grad_(True)
    loss = chamfer_distance(x, y, convention="pytorch3d")
    loss.backward()
    d2 = ((x[:, :, None, :] - y[:, None, :, :]) ** 2).sum(-1)
    x2 = x.detach().clone().requires_grad_(True)
    d2 = ((x2[:, :, None, :] - y[:, None, :, :]) ** 2).sum(-1)
    (d2.min(2).values.mean(1) + d2.min(1).values.mean(1)).mean().backward()
    torch.testing.assert_close(x.grad, x2.grad, rtol=1e-10, atol=1e-12)
    per_row = chamfer_distance(x.detach(), y, reduction="none")
    assert per_row.shape == (3,)
    assert float(chamfer_distance(x.detach(), y, reduction="sum")) == pytest.approx(float(per_row.sum()))


def test_bad_inputs_say_what_is_wrong():
    x = torch.rand(2, 10, 3)
    with pytest.raises(ValueError, match=r"\(B, N, 3\)"):
        chamfer_distance(x[0], x[0])
    with pytest.raises(ValueError, match="convention"):
        chamfer_distance(x, x, convention="open3d")
    with pytest.raises(ValueError, match="threshold_mode"):
        f_score(x, x, 0.1, threshold_mode="side")
    with pytest.raises(ValueError, match="lengths"):
        chamfer_distance(x, x, x_lengths=torch.tensor([0, 10]))
    with pytest.raises(ValueError, match="batch sizes"):
        chamfer_distance(x, x[:1])
