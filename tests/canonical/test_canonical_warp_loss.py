"""The warp head's loss terms (lit3d.canonical.warp_loss): the flow is paid where the posed view shows the
point, the visibility on the canonical foreground, and a batch without flow targets pays neither."""
from types import SimpleNamespace

import pytest
import torch

from lit3d.canonical.warp_loss import warp_terms


def _case():
    canon_mask = torch.zeros(1, 1, 8, 8)
    canon_mask[..., 2:6, 2:6] = 1
    vis = canon_mask.clone()
    vis[..., 2:4, 2:6] = 0  # the upper half of the body is hidden in the posed view
    out = SimpleNamespace(flow=torch.zeros(1, 2, 8, 8), vis_logits=torch.zeros(1, 1, 8, 8), mask=canon_mask)
    batch = {"flow": torch.zeros(1, 2, 8, 8), "vis": vis, "has_flow": torch.tensor([True]), "canon_mask": canon_mask}
    return out, batch, canon_mask, vis


def test_flow_is_paid_on_the_visible_pixels_only():
    out, batch, _, _ = _case()
    batch["flow"][:, 0, 2:4, 2:6] = 4.0  # 4 px = 1 grid unit on 8 px: wrong only on the hidden pixels
    batch["flow"][:, 0, 0, 0] = 4.0      # and on a background pixel
    assert float(warp_terms(out, batch)["flow"]) == pytest.approx(0.0, abs=1e-3)
    batch["flow"][:, 0, 4:6, 2:6] = 4.0  # now wrong on the 8 visible pixels too: 1 grid unit each
    assert float(warp_terms(out, batch)["flow"]) == pytest.approx(1.0, abs=1e-3)


def test_visibility_is_paid_on_the_canonical_foreground_only():
    out, batch, canon_mask, vis = _case()
    out.vis_logits = torch.where(canon_mask > 0.5, torch.where(vis > 0.5, 20.0, -20.0), 20.0)  # right on fg, 1 on bg
    assert float(warp_terms(out, batch)["vis"]) == pytest.approx(0.0, abs=1e-6)
    out.vis_logits = torch.full((1, 1, 8, 8), 20.0)  # the hidden 8 of 16 foreground pixels called seen
    assert float(warp_terms(out, batch)["vis"]) == pytest.approx(20.0 * 8 / 16, rel=1e-4)


def test_a_batch_without_flow_targets_pays_only_the_smoothness():
    out, batch, _, _ = _case()
    out.flow[:, 0, :, 4:] = 1.0  # a step in x: 1 on 8 of the 2 x 8 x 7 horizontal neighbour differences
    terms = warp_terms(out, {"canon_mask": batch["canon_mask"]})
    assert float(terms["flow"]) == 0.0 and float(terms["vis"]) == 0.0
    assert float(terms["smooth"]) == pytest.approx(8 / 112, rel=1e-5)
