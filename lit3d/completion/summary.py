"""Per-component rows (parameters, shapes, activation bytes) of the 3DCascade-GAN for ``lit3d-summary``."""
from __future__ import annotations

import torch

from lit3d.completion.nets import build_completion_nets, validate_net_config
from lit3d.utils.summary import META, summarize


def summarize_completion(cfg: dict) -> list[dict]:
    """Rows for the 3DCascade-GAN at ``cfg`` (``task.nets``, see :func:`lit3d.completion.nets.build_completion_nets`):
    each generator stage with its real input (stage s gets s channels; the last stage also gets the
    stage-1 encoder maps as global skips), each selector, the whole generator, critic, classifier,
    and a total. Batch 1, meta device, nothing allocated."""
    c = validate_net_config(cfg)
    with torch.device(META):
        nets = build_completion_nets(c)
    g = nets["generator"]
    r, R = c["in_res"], c["out_res"]
    rows: list[dict] = []

    n = len(g.stages)
    skip_shapes = [(1, ch, r // 2 ** (i + 1), r // 2 ** (i + 1), r // 2 ** (i + 1)) for i, ch in enumerate(c["enc_channels"])]
    for s, stage in enumerate(g.stages):
        shapes = [(1, s + 1, r, r, r)]
        if s == n - 1 and g.use_global_skips:
            shapes.append(skip_shapes)
        res = summarize(stage, shapes)
        rows.append(dict(component=f"generator stage {s + 1}", params=res["params"], input=(1, s + 1, r, r, r),
                         output=res["output_shape"][0], activation_bytes_per_sample=res["activation_bytes_per_sample"]))
        if stage.selector is not None:
            sel = summarize(stage.selector, [(1, stage.latent_dim)])
            rows.append(dict(component=f"  selector {s + 1} (n={stage.latent_dim}, K={stage.selector.k})",
                             params=sel["params"], input=(1, stage.latent_dim), output=sel["output_shape"][0],
                             activation_bytes_per_sample=sel["activation_bytes_per_sample"]))
    gs = summarize(g, [(1, 1, r, r, r)])
    rows.append(dict(component="generator", params=gs["params"], input=(1, 1, r, r, r), output=gs["output_shape"],
                     activation_bytes_per_sample=gs["activation_bytes_per_sample"]))
    cs = summarize(nets["critic"], [(1, 1, r, r, r), (1, 1, R, R, R)])
    rows.append(dict(component="critic", params=cs["params"], input=[(1, 1, r, r, r), (1, 1, R, R, R)],
                     output=cs["output_shape"], activation_bytes_per_sample=cs["activation_bytes_per_sample"]))
    if "classifier" in nets:
        ks = summarize(nets["classifier"], [(1, 1, R, R, R)])
        rows.append(dict(component="classifier", params=ks["params"], input=(1, 1, R, R, R), output=ks["output_shape"],
                         activation_bytes_per_sample=ks["activation_bytes_per_sample"]))
    rows.append(dict(component="total", params=sum(sum(p.numel() for p in m.parameters()) for m in nets.values())))
    return rows
