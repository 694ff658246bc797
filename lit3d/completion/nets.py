"""3DCascade-GAN networks of thesis chapter 3 (shape completion from one depth view): the factory.

Plain ``nn.Module``s (no Lightning). Every size comes from the config, and only from it:
``conf/task/completion.yaml`` holds the thesis sizes (64^3 -> 256^3), ``experiment=completion_demo``
a demo scale that trains on a CPU (16^3 -> 64^3); ``lit3d-summary experiment=completion_paper``
prints params / memory per component. :func:`build_completion_nets` takes that ``task.nets``
dict with every key of :data:`NET_KEYS` present.

Tensors (B = batch, r = input grid ``in_res``, R = shape grid ``out_res`` = r * 2**len(up_channels)):
    partial input  (B, 1, r, r, r) float32 in {0, 1}
    generator      -> GeneratorOutput.logits (B, 1, R, R, R) float; ``sigmoid(logits)`` is the
                      occupancy probability (logits are returned so the BCE runs from logits in fp32)
    critic(partial, shape (B, 1, R, R, R) probabilities in [0, 1]) -> (B,)
    classifier(shape probabilities (B, 1, R, R, R)) -> (B, n_classes) logits

Parts: :mod:`lit3d.completion.generator` (cascade, :class:`CascadeGenerator`),
:mod:`lit3d.completion.selector` (latent selection), :mod:`lit3d.completion.critic`,
:mod:`lit3d.completion.classifier`.
"""
from __future__ import annotations

import torch.nn as nn

from lit3d.completion.classifier import ShapeClassifier
from lit3d.completion.critic import Critic
from lit3d.completion.generator import CascadeGenerator

ATTENTION_PLACES = ("discriminator", "generator", "both", "none")

# The keys of ``task.nets`` (values: conf/task/completion.yaml, which documents each one).
NET_KEYS = (
    "in_res", "out_res", "stages", "enc_channels", "up_channels", "latent_dim", "selector", "selector_mode",
    "selector_norm",
    "k", "fixed_latent_dim", "global_skips", "input_skip", "attention", "generator_attention_res",
    "critic_channels", "critic_attention_res", "critic_sigmoid", "classifier", "classifier_res",
    "classifier_channels", "n_classes",
)


def validate_net_config(cfg: dict) -> dict:
    """A plain copy of ``cfg`` (``task.nets``) once every key of :data:`NET_KEYS` is present, no
    other key is, ``attention`` is known and ``out_res = in_res * 2**len(up_channels)``.

    Raises:
        ValueError: naming the unknown or missing keys, or the inconsistent value.
    """
    out = dict(cfg)
    unknown = sorted(set(out) - set(NET_KEYS))
    if unknown:
        raise ValueError(f"unknown completion net config keys {unknown}; known: {sorted(NET_KEYS)}")
    missing = [k for k in NET_KEYS if k not in out]
    if missing:
        raise ValueError(f"completion net config lacks {missing}: sizes come from the task config "
                         "(conf/task/completion.yaml, experiment=completion_demo|completion_paper)")
    if out["attention"] not in ATTENTION_PLACES:
        raise ValueError(f"attention='{out['attention']}' unknown; use one of {ATTENTION_PLACES}")
    expect = out["in_res"] * 2 ** len(out["up_channels"])
    if out["out_res"] != expect:
        raise ValueError(f"out_res={out['out_res']} but in_res * 2**len(up_channels) = {expect}")
    return out


def generator_kwargs(cfg: dict) -> dict:
    """:class:`CascadeGenerator` arguments from a ``task.nets`` dict (validated)."""
    c = validate_net_config(cfg)
    return dict(
        in_res=c["in_res"], stages=c["stages"], enc_channels=list(c["enc_channels"]),
        up_channels=list(c["up_channels"]), latent_dim=c["latent_dim"], selector=bool(c["selector"]),
        k=c["k"], selector_mode=c["selector_mode"], selector_norm=bool(c["selector_norm"]),
        fixed_latent_dim=c["fixed_latent_dim"],
        global_skips=bool(c["global_skips"]),
        input_skip=bool(c["input_skip"]),
        attention="generator" if c["attention"] in ("generator", "both") else "none",
        attention_res=c["generator_attention_res"],
    )


def build_completion_nets(cfg: dict) -> dict[str, nn.Module]:
    """Build ``{"generator", "critic"[, "classifier"]}`` from a plain (nested-free) ``task.nets`` dict.

    Every key of :data:`NET_KEYS` must be present (see :func:`validate_net_config`). Ablation
    switches: ``stages`` (1..3), ``selector`` (bool), ``selector_mode``, ``selector_norm``, ``k``,
    ``attention`` (discriminator|generator|both|none), ``classifier`` (bool), ``critic_sigmoid`` (bool).
    """
    c = validate_net_config(cfg)
    nets: dict[str, nn.Module] = {
        "generator": CascadeGenerator(**generator_kwargs(c)),
        "critic": Critic(
            in_res=c["out_res"], channels=list(c["critic_channels"]), attention_res=c["critic_attention_res"],
            use_attention=c["attention"] in ("discriminator", "both"), sigmoid=bool(c["critic_sigmoid"]),
        ),
    }
    if c["classifier"]:
        nets["classifier"] = ShapeClassifier(c["classifier_res"], list(c["classifier_channels"]), c["n_classes"])
    return nets
