"""The warp and splat heads' loss terms (lit3d.canonical.warp_loss): where the flow and the visibility are
paid, the squared distance, the frame each head's targets live in."""
import pytest
import torch


def test_flow_and_visibility_are_paid_where_asked():
    """``task.warp.flow_on``: ``visible`` pays the flow only where the posed view shows the point, ``foreground``
    on every canonical foreground pixel; neither pays the background. ``task.warp.vis_on``: ``image`` pays the
    visibility on the background too (target 0), ``foreground`` does not."""
    from types import SimpleNamespace

    from lit3d.canonical.warp_loss import warp_terms

    canon_mask = torch.zeros(1, 1, 8, 8)
    canon_mask[..., 2:6, 2:6] = 1
    vis = canon_mask.clone()
    vis[..., 2:4, 2:6] = 0  # the upper half of the body is hidden in the posed view
    flow = torch.zeros(1, 2, 8, 8)
    out = SimpleNamespace(flow=flow, vis_logits=torch.zeros(1, 1, 8, 8), mask=canon_mask, depth=canon_mask,
                          depth_offset=None, flow_frame="canonical")
    batch = {"flow": torch.zeros(1, 2, 8, 8), "vis": vis, "has_flow": torch.tensor([True]), "canon_mask": canon_mask,
             "canon_depth": canon_mask, "mask": torch.ones_like(canon_mask)}
    batch["flow"][:, 0, 2:4, 2:6] = 4.0  # 4 px = 1 grid unit on 8 px: wrong only on the hidden pixels
    batch["flow"][:, 0, 0, 0] = 4.0      # and on a background pixel, which neither pays
    assert float(warp_terms(out, batch, "visible")["flow"]) == pytest.approx(0.0, abs=1e-3)
    assert float(warp_terms(out, batch, "foreground")["flow"]) == pytest.approx(0.5, abs=1e-3)  # 8 of 16 pixels
    with pytest.raises(ValueError, match="flow_on"):
        warp_terms(out, batch, "everywhere")
    # flow_power=2: the squared distance (1 grid unit on 8 of 16 pixels: 0.5 either way; 2 units: 2.0 against 1.0)
    assert float(warp_terms(out, batch, "foreground", flow_power=2.0)["flow"]) == pytest.approx(0.5, abs=1e-3)
    batch["flow"] = batch["flow"] * 2
    assert float(warp_terms(out, batch, "foreground", flow_power=2.0)["flow"]) == pytest.approx(2.0, abs=1e-3)
    assert float(warp_terms(out, batch, "foreground")["flow"]) == pytest.approx(1.0, abs=1e-3)
    batch["flow"] = batch["flow"] / 2
    # vis_on: "foreground" leaves the background's visibility free, "image" pays it with target 0
    out.vis_logits = torch.where(canon_mask > 0.5, torch.where(vis > 0.5, 20.0, -20.0), 20.0)  # right on fg, 1 on bg
    assert float(warp_terms(out, batch, vis_on="foreground")["vis"]) == pytest.approx(0.0, abs=1e-6)
    assert float(warp_terms(out, batch, vis_on="image")["vis"]) == pytest.approx(20.0 * 48 / 64, rel=1e-4)
    with pytest.raises(ValueError, match="vis_on"):
        warp_terms(out, batch, vis_on="nowhere")
    # the splat head's flow lives at the posed pixels: its targets are the forward ones, its foreground the posed mask
    out.flow_frame = "posed"
    batch.update(fflow=torch.zeros(1, 2, 8, 8), fvis=torch.zeros(1, 1, 8, 8), mask=canon_mask.clone())
    batch["fflow"][:, 1, 2:6, 2:6] = -8.0  # 2 grid units upwards on the 16 posed body pixels
    assert float(warp_terms(out, batch, "visible")["flow"]) == pytest.approx(0.0, abs=1e-3)  # none seen: nothing paid
    assert float(warp_terms(out, batch, "foreground")["flow"]) == pytest.approx(2.0, abs=1e-3)
    # a batch with backward targets only (data.render.forward_flow=false) cannot teach the splat head: said, not skipped
    with pytest.raises(ValueError, match="data.render.forward_flow=true"):
        warp_terms(out, {k: v for k, v in batch.items() if k not in ("fflow", "fvis")}, "foreground")
