"""Depth-image metrics of the canonical task (lit3d.metrics.depth) against brute-force NumPy loops,
and the gathered test outputs (lit3d.metrics.gathered)."""
import numpy as np
import pytest
import torch

from lit3d.metrics.depth import MaskedDepthMSE, MaskIoU, per_sample_depth_mse, per_sample_mask_iou
from lit3d.metrics.gathered import GatheredTensors


def _depth_mse_reference(dh, mh, d, m, thr):
    """Pixel loop: composited prediction vs true depth (background 0) over the union of the masks."""
    out = []
    for b in range(dh.shape[0]):
        err, n = 0.0, 0
        for y in range(dh.shape[2]):
            for x in range(dh.shape[3]):
                pred_in, true_in = mh[b, 0, y, x] >= thr, m[b, 0, y, x] >= 0.5
                if pred_in or true_in:
                    p = dh[b, 0, y, x] if pred_in else 0.0
                    t = d[b, 0, y, x] if true_in else 0.0
                    err += (p - t) ** 2
                    n += 1
        out.append(err / n if n else 0.0)
    return np.array(out)


def _iou_reference(mh, m, thr):
    out = []
    for b in range(mh.shape[0]):
        p, t = mh[b] >= thr, m[b] >= 0.5
        union = np.logical_or(p, t).sum()
        out.append(np.logical_and(p, t).sum() / union if union else 1.0)
    return np.array(out)


def _batch(seed, b=5, s=9):
    rng = np.random.default_rng(seed)
    dh, mh, d = (rng.random((b, 1, s, s)).astype(np.float32) for _ in range(3))
    m = (rng.random((b, 1, s, s)) > 0.5).astype(np.float32)
    mh[0], m[0] = 0.0, 0.0  # both masks empty: MSE 0, IoU 1
    if b > 1:
        mh[1] = 0.0  # prediction empty, target not
    return dh, mh, d, m


@pytest.mark.parametrize("thr", [0.5, 0.3])
def test_per_sample_functions_match_pixel_loops(thr):
    dh, mh, d, m = _batch(0)
    t = [torch.from_numpy(a) for a in (dh, mh, d, m)]
    mse = per_sample_depth_mse(*t, threshold=thr).numpy()
    np.testing.assert_allclose(mse, _depth_mse_reference(dh, mh, d, m, thr), rtol=1e-5, atol=1e-7)
    assert mse[0] == 0
    iou = per_sample_mask_iou(t[1], t[3], threshold=thr).numpy()
    np.testing.assert_allclose(iou, _iou_reference(mh, m, thr), rtol=1e-6)
    assert iou[0] == 1 and iou[1] == 0


def test_metrics_average_per_sample_values_over_uneven_batches():
    batches = [_batch(seed, b) for seed, b in ((1, 5), (2, 3), (3, 1))]
    mse, iou = MaskedDepthMSE(0.4), MaskIoU(0.4)
    for dh, mh, d, m in batches:
        t = [torch.from_numpy(a) for a in (dh, mh, d, m)]
        mse.update(*t)
        iou.update(t[1], t[3])
    want_mse = np.concatenate([_depth_mse_reference(*b, 0.4) for b in batches]).mean()
    want_iou = np.concatenate([_iou_reference(b[1], b[3], 0.4) for b in batches]).mean()
    assert float(mse.compute()) == pytest.approx(want_mse, rel=1e-5)
    assert float(iou.compute()) == pytest.approx(want_iou, rel=1e-6)
    # sum states: merging two halves (as the DDP reduction does) gives the same mean
    a, b = MaskedDepthMSE(0.4), MaskedDepthMSE(0.4)
    for i, (dh, mh, d, m) in enumerate(batches):
        (a if i == 0 else b).update(*(torch.from_numpy(x) for x in (dh, mh, d, m)))
    a.merge_state(b)
    assert float(a.compute()) == pytest.approx(want_mse, rel=1e-5)
    assert float(MaskIoU().compute()) == 0  # nothing seen


def test_gathered_tensors_concatenate_updates_and_reset():
    g = GatheredTensors(("depth", "label"))
    assert g.compute() == {}
    g.update(depth=torch.zeros(2, 1, 4, 4), label=torch.tensor([3, 4]))
    g.update(depth=torch.ones(1, 1, 4, 4), label=torch.tensor([5]))
    out = g.compute()
    assert out["depth"].shape == (3, 1, 4, 4) and out["label"].tolist() == [3, 4, 5]
    assert out["label"].dtype == torch.int64 and float(out["depth"][2].min()) == 1
    with pytest.raises(ValueError, match="batch size"):
        g.update(depth=torch.zeros(2, 1, 4, 4), label=torch.tensor([1]))
    with pytest.raises(ValueError, match="exactly"):
        g.update(depth=torch.zeros(1, 1, 4, 4))
    g.reset()
    assert g.compute() == {}
