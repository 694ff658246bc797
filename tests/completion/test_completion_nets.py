"""3DCascade-GAN nets: selector, generator shapes and ablations, self-attention, critic, classifier."""
from __future__ import annotations

import pytest
import torch

from lit3d.completion.attention import SelfAttention3d
from lit3d.completion.classifier import ShapeClassifier
from lit3d.completion.critic import Critic
from lit3d.completion.generator import CascadeGenerator, GeneratorOutput
from lit3d.completion.nets import NET_KEYS, build_completion_nets, validate_net_config
from lit3d.completion.selector import LatentSelector


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def _partial(b=2, r=16, seed=0):
    g = torch.Generator().manual_seed(seed)
    return (torch.rand(b, 1, r, r, r, generator=g) < 0.2).float()


# ---------------------------------------------------------------- selector
@pytest.mark.parametrize("mode", ["straight_through", "literal"])
def test_selector_keeps_exactly_k_in_place(mode):
    torch.manual_seed(0)
    sel = LatentSelector(64, 10, mode)
    latent = torch.randn(5, 64)
    out, mask = sel(latent)
    assert out.shape == latent.shape and mask.shape == latent.shape
    assert ((out != 0).sum(1) == 10).all()
    assert (mask.sum(1) == 10).all()
    # kept entries keep value and position; they are the top-K of the weight net
    assert torch.equal(out, latent * mask)
    w = sel.weight_net(latent)
    top = torch.topk(w, 10, dim=1).indices
    assert torch.equal(mask.gather(1, top), torch.ones(5, 10))


def test_selector_straight_through_vs_literal_gradients():
    torch.manual_seed(0)
    st = LatentSelector(32, 4, "straight_through")
    lit = LatentSelector(32, 4, "literal")
    lit.load_state_dict(st.state_dict())
    latent = torch.randn(3, 32, requires_grad=True)
    target = torch.randn(3, 32)
    for sel in (st, lit):
        out, _ = sel(latent)
        ((out - target) ** 2).sum().backward()
    st_grad = sum(p.grad.abs().sum() for p in st.weight_net.parameters())
    assert st_grad > 0
    assert all(p.grad is None or p.grad.abs().sum() == 0 for p in lit.weight_net.parameters())
    # same forward value in both modes
    assert torch.equal(st(latent)[0], lit(latent)[0])


# ---------------------------------------------------------------- generator
def test_generator_demo_shapes_and_outputs(completion_demo_nets):
    torch.manual_seed(0)
    demo = completion_demo_nets
    g = build_completion_nets(demo)["generator"]
    out = g(_partial(2))
    assert isinstance(out, GeneratorOutput)
    assert out.logits.shape == (2, 1, 64, 64, 64)
    assert [tuple(s.shape) for s in out.stage_logits] == [(2, 1, 16, 16, 16)] * 2 + [(2, 1, 64, 64, 64)]
    assert out.stage_logits[-1] is out.logits
    assert out.keep_fraction.shape == () and out.keep_fraction.item() == pytest.approx(demo["k"] / demo["latent_dim"])
    # stage inputs have 1, 2, 3 channels; the last stage gets the stage-1 global skips
    assert [s.encoder[0][0][1].in_channels for s in g.stages] == [1, 2, 3]
    assert g.use_global_skips


def test_generator_global_skips_change_last_stage_decoder():
    kw = dict(in_res=16, stages=2, enc_channels=(4, 8), up_channels=(4,), latent_dim=16, k=4)
    with_gs = CascadeGenerator(**kw, global_skips=True)
    without = CascadeGenerator(**kw, global_skips=False)
    # decoder level 0 input: fc map (8) + local skip (8) [+ global skip (8)]
    assert with_gs.stages[-1].decoder[0].in_channels == 24
    assert without.stages[-1].decoder[0].in_channels == 16
    assert with_gs(_partial(1)).logits.shape == (1, 1, 32, 32, 32)



def test_input_skip_feeds_the_stage_input_to_the_up_sampling():
    kw = dict(in_res=16, stages=3, enc_channels=(4, 8), up_channels=(4, 2), latent_dim=16, k=4)
    skip, plain = CascadeGenerator(**kw, input_skip=True), CascadeGenerator(**kw, input_skip=False)
    # first up layer: up_channels[0] decoder channels [+ the 3-channel last-stage input]
    assert skip.stages[-1].up[0].in_channels == 4 + 3 and plain.stages[-1].up[0].in_channels == 4
    assert all(not st.input_skip for st in skip.stages[:-1])
    # the skip is a real path: the partial input reaches the output even with the decoder zeroed
    for p in skip.stages[-1].decoder.parameters():
        torch.nn.init.zeros_(p)
    x = _partial(1).requires_grad_(True)
    skip(x).logits.sum().backward()
    assert x.grad.abs().sum() > 0


ABLATIONS = [
    {"stages": 1},
    {"stages": 2},
    {"selector": False},
    {"selector_mode": "literal"},
    {"k": 8},
    {"attention": "generator"},
    {"attention": "none"},
    {"attention": "both"},
    {"classifier": False},
    {"critic_sigmoid": False},
    {"critic_sigmoid": True},
    {"global_skips": False},
    {"input_skip": False},
]


@pytest.mark.parametrize("switch", ABLATIONS, ids=lambda d: ",".join(f"{k}={v}" for k, v in d.items()))
def test_every_ablation_builds_and_runs_at_demo_scale(switch, completion_demo_nets):
    torch.manual_seed(0)
    cfg = {**completion_demo_nets, **switch}
    nets = build_completion_nets(cfg)
    c = validate_net_config(cfg)
    g, d = nets["generator"], nets["critic"]
    x = _partial(1)
    out = g(x)
    assert out.logits.shape == (1, 1, 64, 64, 64)
    assert len(out.stage_logits) == c["stages"]
    if c["selector"]:
        assert out.keep_fraction.item() == pytest.approx(c["k"] / c["latent_dim"])
        assert g.stages[0].latent_dim == c["latent_dim"]
    else:
        assert out.keep_fraction.item() == 1.0
        assert all(s.selector is None and s.latent_dim == c["fixed_latent_dim"] for s in g.stages)
    gen_attn = any(isinstance(m, SelfAttention3d) for m in g.modules())
    assert gen_attn == (c["attention"] in ("generator", "both"))
    assert (d.attn is not None) == (c["attention"] in ("discriminator", "both"))
    score = d(x, torch.sigmoid(out.logits))
    assert score.shape == (1,)
    if c["critic_sigmoid"]:
        assert ((score > 0) & (score < 1)).all()
    assert ("classifier" in nets) == c["classifier"]
    if c["classifier"]:
        assert nets["classifier"](torch.sigmoid(out.logits)).shape == (1, 4)
    # gradients reach the first encoder layer
    (score.sum() + out.logits.mean()).backward()
    assert g.stages[0].encoder[0][0][1].weight.grad.abs().sum() > 0


def test_bad_config_is_rejected(completion_demo_nets):
    demo = completion_demo_nets
    with pytest.raises(ValueError, match="unknown completion net config keys"):
        build_completion_nets({**demo, "stagse": 2})
    with pytest.raises(ValueError, match="out_res"):
        build_completion_nets({**demo, "out_res": 128})
    with pytest.raises(ValueError, match="stages"):
        build_completion_nets({**demo, "stages": 4})
    # no size presets in Python: a size left out is an error naming it, never a silent default
    with pytest.raises(ValueError, match=r"lacks \['latent_dim'\]"):
        build_completion_nets({k: v for k, v in demo.items() if k != "latent_dim"})
    with pytest.raises(ValueError, match="unknown completion net config keys \\['preset'\\]"):
        build_completion_nets({**demo, "preset": "demo"})


def test_the_configs_name_every_net_key_and_only_those(completion_demo_nets, completion_paper_nets):
    assert set(completion_demo_nets) == set(NET_KEYS) == set(completion_paper_nets)
    assert (completion_demo_nets["in_res"], completion_demo_nets["out_res"]) == (16, 64)
    assert (completion_paper_nets["in_res"], completion_paper_nets["out_res"]) == (64, 256)


# ---------------------------------------------------------------- self-attention
def test_self_attention_gamma_zero_is_identity():
    torch.manual_seed(0)
    att = SelfAttention3d(16)
    x = torch.randn(2, 16, 4, 4, 4)
    assert att.gamma.item() == 0.0
    assert torch.equal(att(x), x)


def test_self_attention_sdpa_equals_explicit_softmax():
    torch.manual_seed(0)
    att = SelfAttention3d(16, reduction=4)
    with torch.no_grad():
        att.gamma.fill_(0.7)
    x = torch.randn(2, 16, 4, 5, 3)
    att.use_sdpa = True
    a = att(x)
    att.use_sdpa = False
    b = att(x)
    # independent reference: SAGAN eqs. 3.2-3.4 written out with einsum
    f = att.f(x).flatten(2)
    g = att.g(x).flatten(2)
    h = att.h(x).flatten(2)
    beta = torch.softmax(torch.einsum("bci,bcj->bji", f, g), dim=-1)  # beta[j, i]
    o = att.v(torch.einsum("bji,bci->bcj", beta, h).reshape(2, -1, 4, 5, 3))
    ref = 0.7 * o + x
    torch.testing.assert_close(a, ref, rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(b, ref, rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(att.attention_map(x), beta, rtol=1e-5, atol=1e-6)
    assert not torch.allclose(a, x)


# ---------------------------------------------------------------- critic / classifier
def test_critic_shapes_and_sigmoid_bound():
    torch.manual_seed(0)
    x = _partial(3)
    y = torch.rand(3, 1, 64, 64, 64)
    plain = Critic(64, (8, 8, 8, 8), attention_res=8, sigmoid=False)
    assert plain.attn_after == 2  # 64 -> 32 -> 16 -> 8: attention after the third layer
    with torch.no_grad():
        plain.layers[-1][0].bias.fill_(50.0)
    s = plain(x, y)
    assert s.shape == (3,) and (s > 1).all()  # unbounded WGAN critic
    sig = Critic(64, (8, 8, 8, 8), attention_res=8, sigmoid=True)
    sig.load_state_dict(plain.state_dict())
    t = sig(x, y)
    assert t.shape == (3,) and ((t > 0) & (t <= 1)).all()
    with pytest.raises(ValueError, match="no layer output"):
        Critic(64, (8, 8), attention_res=8)


def test_critic_sees_the_partial_input():
    torch.manual_seed(0)
    c = Critic(32, (4, 4, 4), use_attention=False)
    y = torch.rand(2, 1, 32, 32, 32)
    a = c(torch.zeros(2, 1, 8, 8, 8), y)
    b = c(torch.ones(2, 1, 8, 8, 8), y)
    assert not torch.allclose(a, b)


def test_classifier_layers_fit_the_grid():
    clf = ShapeClassifier(in_res=64, channels=(4, 4, 4, 4, 4, 4, 4), n_classes=4)
    convs = [m for m in clf.features.modules() if isinstance(m, torch.nn.Conv3d)]
    assert len(convs) == 4  # 64 -> 32 -> 16 -> 8 -> 4: the thesis's 7 layers do not fit
    assert clf.head.in_features == 4 * 4**3
    # input at 4x the grid is max-pooled: a single occupied voxel survives pooling
    y = torch.zeros(2, 1, 256, 256, 256)
    y[0, 0, 5, 5, 5] = 1
    assert clf(y).shape == (2, 4)
    pooled = torch.nn.functional.max_pool3d(y, 4)
    assert pooled[0, 0, 1, 1, 1] == 1


def test_thesis_experiment_is_the_paper_sizes_in_the_thesis_form(compose_cfg):
    """completion_thesis = the thesis's exact form (no input skip, last-stage BCE only, critic from
    step 0) at the sizes of completion_paper, which keeps the measured additions on."""
    thesis, paper = (compose_cfg([f"experiment=completion_{n}"]).task for n in ("thesis", "paper"))
    assert (thesis.nets.input_skip, thesis.loss.stage_weight, thesis.adversarial.use, thesis.adversarial.start_epoch) == (
        False, 0.0, True, 0)
    assert (paper.nets.input_skip, paper.loss.stage_weight) == (True, 0.5)
    assert {k: v for k, v in thesis.nets.items() if k != "input_skip"} == \
        {k: v for k, v in paper.nets.items() if k != "input_skip"}
    assert thesis.optimizer.loss_scale == paper.optimizer.loss_scale == "voxels"
