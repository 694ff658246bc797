"""The warp head's mask-IoU breakdown: an untrained head scores as its posed input, the oracle row (true
flow, visibility and fill) scores the flow targets' own fidelity, and a net without a warp head is refused."""
import numpy as np
import pytest
import torch
from omegaconf import OmegaConf

from datamodules.canonical.rendering import PairRenderer
from datamodules.canonical.settings import RenderSettings
from datamodules.canonical.sources import SynthSource
from lit3d.canonical.factory import build_canonical_net
from studies.canonical.warp_breakdown import PICTURE_COLUMNS, ROWS, breakdown, markdown, picture, summarise

SIZE = 64
RENDER = RenderSettings(azimuths=(0.0,), view_mode="fixed", scale_mode="shape", flow_targets=True)


def _batch() -> dict:
    """Every pose of two procedural figures (a humanoid, a quadruped) at 64², with flow targets."""
    src = SynthSource(["humanoid", "quadruped"], 2, 3, 0, 32, 0, 15.0, 1.0)
    size = SIZE

    def unpack(a):
        return np.unpackbits(a)[: size * size].reshape(size, size).astype(np.float32)

    items = []
    for subject in src.subjects():
        a = PairRenderer(src, RENDER, SIZE).render_subject(subject)
        for p in a["poses"]:
            items.append({"depth": a[f"depth_{p}_0"].astype(np.float32)[None], "mask": unpack(a[f"mask_{p}_0"])[None],
                          "canon_depth": a["depth_canonical_0"].astype(np.float32)[None],
                          "canon_mask": unpack(a["mask_canonical_0"])[None],
                          "flow": a[f"flow_{p}_0"].astype(np.float32), "vis": unpack(a[f"vis_{p}_0"])[None]})
    return {k: torch.as_tensor(np.stack([it[k] for it in items])) for k in items[0]}


def test_breakdown_of_an_untrained_head_and_its_oracle(compose_cfg):
    cfg = compose_cfg(["experiment=canonical_tiny", "task.net.head.kind=warp", "data.image_size=64"])
    net = build_canonical_net({"kind": "canonical", **OmegaConf.to_container(cfg.task.net, resolve=True)}).eval()
    batch = _batch()
    figures = breakdown(net, batch)
    assert all(len(figures[name]) == 6 for name, *_ in ROWS)
    # an untrained head returns its input: the model scores as the posed input, well below the oracle
    assert torch.allclose(figures["the model"], figures["posed input"], atol=0.03)
    assert float(figures[ROWS[-1][0]].min()) >= 0.95  # the oracle: the flow targets reproduce the truth
    assert float(figures["posed input"].mean()) < 0.8
    # the true flow on the body moves the body: better than the untrained (zero) flow
    assert float(figures["true flow on the body, true fill"].mean()) > float(figures["true fill"].mean())
    means = summarise([figures])
    assert means["flow error, visible (px)"] > 0.5  # zero flow against a pose change
    table = markdown(means, 6, "an untrained net")
    assert "| the model |" in table and "(6 items)" in table
    image = picture(net, batch, "untrained", n=2, cell=256)  # 2 rows of 256-px cells, one column each
    assert image.size[0] >= 256 * len(PICTURE_COLUMNS) and image.size[1] >= 2 * 256


def test_breakdown_refuses_a_net_without_a_warp_head(compose_cfg):
    cfg = compose_cfg(["experiment=canonical_tiny", "task.net.head.kind=redraw"])
    net = build_canonical_net({"kind": "canonical", **OmegaConf.to_container(cfg.task.net, resolve=True)})
    with pytest.raises(ValueError, match="warp head"):
        breakdown(net, {})


def test_command_refuses_bad_input_and_outputs_over_its_input(tmp_path, capsys):
    """A missing or broken checkpoint and an output that would replace the checkpoint: one line, exit 2,
    the checkpoint untouched."""
    from studies.canonical.warp_breakdown import main

    bad = tmp_path / "run.ckpt"
    bad.write_text("not a checkpoint\n")
    cases = [([str(tmp_path / "missing.ckpt")], "checkpoint not found"),
             ([str(bad)], "not a readable checkpoint"),
             ([str(bad), "--out", str(bad)], "would replace the input"),
             ([str(bad), "--picture", str(tmp_path)], "exists as a folder")]
    for argv, message in cases:
        assert main(argv) == 2, argv
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0], (argv, err)
    assert bad.read_text() == "not a checkpoint\n"
