"""The splat head: zero flow gives the input exactly, the splat is differentiable in the flow, an untrained
head returns its input (that the true forward flow lands on the canonical silhouette and that the head
learns a flow it is shown: tests/test_canonical_warp.py, beside the warp head's)."""
import torch
from omegaconf import OmegaConf

from lit3d.canonical.factory import build_canonical_net
from lit3d.canonical.splat import SplatHead, forward_splat
from lit3d.canonical.warp import pixels_to_grid


def test_zero_flow_splat_reproduces_its_input_exactly():
    g = torch.Generator().manual_seed(0)
    values = torch.rand(2, 3, 20, 28, generator=g)
    weight = (torch.rand(2, 1, 20, 28, generator=g) > 0.4).float()
    sums, w = forward_splat(values, weight, torch.zeros(2, 2, 20, 28))
    assert torch.allclose(w, weight, atol=1e-6) and torch.allclose(sums, values * weight, atol=1e-6)
    # a whole-pixel flow moves the image by that many pixels; what leaves the image is dropped
    two = pixels_to_grid(torch.tensor([2.0, -1.0]).view(1, 2, 1, 1).expand(2, 2, 20, 28))
    sums, w = forward_splat(values, weight, two)
    assert torch.allclose(w[..., :-1, 2:], weight[..., 1:, :-2], atol=1e-5)
    assert float(w[..., :, :2].abs().max()) < 1e-6 and float(w.sum()) < float(weight.sum())
    # half a pixel shares each pixel between two neighbours, and the shares carry a gradient to the flow
    half = pixels_to_grid(torch.tensor([0.5, 0.0]).view(1, 2, 1, 1).expand(2, 2, 20, 28)).clone().requires_grad_()
    sums, w = forward_splat(values, weight, half)
    assert torch.allclose(w[..., 1:-1], 0.5 * (weight[..., :-2] + weight[..., 1:-1]), atol=1e-5)
    (w * torch.arange(28.0)).sum().backward()  # moving right raises this sum: the gradient says so
    assert half.grad is not None and float(half.grad[:, 0].sum()) > 0


def test_untrained_splat_net_returns_its_input(compose_cfg):
    net_cfg = OmegaConf.to_container(compose_cfg(["experiment=canonical_tiny", "task.net.head.kind=splat"]).task.net,
                                     resolve=True)
    net = build_canonical_net({"kind": "canonical", **net_cfg})
    assert isinstance(net.head, SplatHead)
    depth = torch.rand(2, 1, 48, 48)
    mask = (depth > 0.5).float()
    depth = depth * mask
    out = net(depth, mask)
    assert out.flow_frame == "posed" and out.flow.abs().max() == 0 and out.flow.shape == (2, 2, 48, 48)
    assert (out.depth - depth).abs().max() < 0.03 and (out.mask - mask).abs().max() < 0.03
