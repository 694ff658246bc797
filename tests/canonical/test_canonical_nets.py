"""Canonical nets: size-agnostic blocks, ablation switches, thesis sizes at 500^2 (meta device).

Net sizes come from the configs (the only source of sizes): the task config's demo nets at 64^2
and experiment=canonical_paper's thesis nets."""
import pytest
import torch
from omegaconf import OmegaConf

from lit3d.canonical.factory import build_canonical_net, summarize
from lit3d.canonical.nets import LFE, MSFE, CanonicalNet, UNet


def _net_sizes(compose_cfg, *overrides: str) -> dict:
    """CanonicalNet kwargs of a composed task config (``unet_channels`` dropped)."""
    net = OmegaConf.to_container(compose_cfg(["task=canonical", *overrides]).task.net, resolve=True)
    net.pop("unet_channels", None)
    net.pop("recall_channels", None)
    net.pop("init", None)
    return net


@pytest.fixture
def small(compose_cfg) -> dict:
    return _net_sizes(compose_cfg, "task.net.image_size=64")


@pytest.mark.parametrize("size", [33, 64, 75])
def test_blocks_return_input_size(size, small):
    x = torch.rand(2, 2, size, size)
    assert LFE(2, 3, (4, 8, 8))(x).shape == (2, 3, size, size)
    m = MSFE(2, 2, (4, 4, 2), grid=4, fuser_hidden=16, fuser_out=8, dec_channels=(8, 8, 4, 4, 4, 4), image_size=size)
    assert m(x).shape == (2, 2, size, size)
    out = CanonicalNet(**small)(x[:, :1], x[:, 1:])
    assert out.depth.shape == out.mask.shape == (2, 1, size, size)
    assert 0 <= out.depth.min() and out.depth.max() <= 1 and 0 <= out.mask.min() and out.mask.max() <= 1
    assert UNet((4, 8), size)(x[:, :1], x[:, 1:]).depth.shape == (2, 1, size, size)


def test_non_square_input(small):
    d = torch.rand(1, 1, 40, 56)
    assert CanonicalNet(**small)(d, d).depth.shape == (1, 1, 40, 56)


def test_ablation_switches_drop_components_and_still_train(small):
    for lfe, msfe in [(True, True), (False, True), (True, False), (False, False)]:
        net = CanonicalNet(**{**small, "lfe": {**small["lfe"], "use": lfe}, "msfe": {**small["msfe"], "use": msfe}})
        assert (net.lfe is not None) == lfe and (net.msfe is not None) == msfe
        d = torch.rand(2, 1, 32, 32)
        out = net(d, (d > 0.5).float())
        (out.depth.mean() + out.mask.mean()).backward()
        assert all(p.grad is not None for p in net.parameters() if p.requires_grad)


def test_paper_sizes_at_500(compose_cfg):
    paper = _net_sizes(compose_cfg, "experiment=canonical_paper")
    with torch.device("meta"):
        net = CanonicalNet(**paper)
        rows = {r["component"]: r for r in summarize(net, 500)}
    for d in (1, 2, 3):
        assert rows[f"MSFE encoder d={d}"]["output"] == (1, 16000)
    assert net.msfe.latent_dim == 48000
    assert rows["MSFE fuser"]["output"] == (1, 500)
    assert rows["LFE"]["output"] == (1, 1, 500, 500)
    assert rows["MSFE decoder"]["output"] == (1, 1, 500, 500)
    assert [m.kernel_size[0] for m in net.msfe.decoder if isinstance(m, torch.nn.ConvTranspose2d)] == [3, 3, 6, 2, 2, 2, 3]
    assert [m.kernel_size[0] for m in net.lfe.up if isinstance(m, torch.nn.ConvTranspose2d)] == [5, 3, 5, 2, 2]


def test_build_from_plain_dict(small):
    assert isinstance(build_canonical_net({"kind": "unet", "channels": [4, 8], "image_size": 32}), UNet)
    assert isinstance(build_canonical_net({"kind": "canonical", **small}), CanonicalNet)
    with pytest.raises(ValueError, match="unknown"):
        build_canonical_net({"kind": "nope"})


@pytest.mark.parametrize("size", [64, 128])
def test_he_init_keeps_the_global_path_alive(compose_cfg, size):
    """PyTorch's default init shrinks the MSFE's 12 layers until its output is one image for every input
    (measured on TOSCA: spread 4e-8); the He init (transposed convs counted by stride) keeps inputs apart."""
    net_cfg = OmegaConf.to_container(compose_cfg(["task=canonical", f"task.net.image_size={size}"]).task.net,
                                     resolve=True)
    assert net_cfg["init"] == "he"  # the configured default
    torch.manual_seed(0)
    d = torch.rand(4, 1, size, size)
    m = (d > 0.5).float()
    x = torch.cat([d * m, m], 1)
    spread = {}
    for init in ("he", "torch"):
        torch.manual_seed(1)
        net = build_canonical_net({**net_cfg, "init": init})
        feats = torch.cat([x, net.lfe(x)], 1)
        with torch.no_grad():
            y = net.msfe(feats)
        spread[init] = (y.std(0).mean() / y.pow(2).mean().sqrt().clamp_min(1e-12)).item()
    assert spread["he"] > 1e-2, spread  # measured .04-.09
    assert spread["torch"] < 1e-4, spread  # measured 4e-8
    with pytest.raises(ValueError, match="init"):
        build_canonical_net({**net_cfg, "init": "xavier"})


# make test-all: 30-90 s, and its margin depends on the thread count (measured with OMP_NUM_THREADS=1: IoU
# he .68, torch .83; with 2 threads he > .9). The cheap check of the init stays in the default suite
# (test_he_init_keeps_the_global_path_alive).
@pytest.mark.slow
def test_he_init_fits_training_pairs_that_the_default_init_does_not(compose_cfg, tmp_path):
    """The training claim behind the init: on 6 rendered pairs (64^2, the demo net, full batch, Adam 1e-3,
    150 steps) the He-initialised net fits the canonical masks (measured IoU .94); PyTorch's default
    init, whose global path starts dead, is still at .83."""
    from datamodules.canonical import CanonicalDataModule
    from lit3d.canonical.losses import canonical_loss

    net_cfg = OmegaConf.to_container(
        compose_cfg(["task=canonical", "task.net.image_size=64", "task.net.head.kind=redraw"]).task.net, resolve=True)
    dm = CanonicalDataModule.from_flat(str(tmp_path / "data"), image_size=64, n_subjects=6, n_poses=4, mesh_resolution=24,
                             n_folds=2, kinds=["humanoid", "quadruped"], seed=1, split="pose", view_mode="broadside")
    dm.prepare_data()
    dm.setup()
    ds = dm.datasets["train"]
    batch = {k: torch.stack([ds[i][k] for i in range(len(ds))]) for k in ("depth", "mask", "canon_depth", "canon_mask")}
    iou = {}
    for init in ("he", "torch"):
        torch.manual_seed(0)
        net = build_canonical_net({**net_cfg, "init": init})
        opt = torch.optim.Adam(net.parameters(), 1e-3)
        for _ in range(150):
            out = net(batch["depth"], batch["mask"])
            loss = canonical_loss(out.depth, out.mask, batch["canon_depth"], batch["canon_mask"], 1000.0, 1000.0,
                                  "bce", out.mask_logits)["loss"]
            opt.zero_grad()
            loss.backward()
            opt.step()
        pm, tm = out.mask.detach() > 0.5, batch["canon_mask"] > 0.5
        iou[init] = ((pm & tm).sum((1, 2, 3)) / (pm | tm).sum((1, 2, 3)).clamp_min(1)).mean().item()
    assert iou["he"] > 0.9, iou
    assert iou["he"] - iou["torch"] > 0.05, iou
