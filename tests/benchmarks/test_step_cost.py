"""The cost model of a training step (lit3d.utils.step_cost, lit3d.completion.step_cost, benchmarks.bench_step_cost):
FLOPs from PyTorch's formulas on the meta device, saved-for-backward bytes, the GPU rows' fraction of peak."""
from __future__ import annotations

import json

import pytest
import torch

from lit3d.completion.checkpoint_upgrade import upgrade_hparams
from lit3d.completion.module import CompletionTask
from lit3d.completion.step_cost import completion_step_cost
from lit3d.utils.step_cost import CostCounter, SavedBytes
from tests.helpers.completion import tiny_nets

META = torch.device("meta")


def _meta_task(nets: dict, **kw) -> CompletionTask:
    with torch.device(META):
        return CompletionTask(**upgrade_hparams({"nets": nets, **kw}))  # kw by their short names (gp_every=2)


def test_conv3d_flops_are_two_multiply_adds_per_weight_and_output_voxel():
    n, cin, cout, k = 3, 2, 5, 4
    with torch.device(META):
        conv = torch.nn.Conv3d(cin, cout, k, stride=2, padding=1)
        x = torch.zeros(n, cin, 16, 16, 16)
    with CostCounter() as c:
        y = conv(x)
    assert y.shape[-1] == 8
    forward = 2 * cin * cout * k**3 * 8**3 * n
    assert c.flops == forward and c.ops == 1
    x.requires_grad_(True)
    with CostCounter() as c:
        conv(x).sum().backward()
    assert c.flops == 3 * forward  # forward + the gradients of the input and of the weight


def test_saved_bytes_of_a_conv_are_its_input_and_weight_and_are_released():
    with torch.device(META):
        conv = torch.nn.Conv3d(2, 5, 3)
        x = torch.zeros(4, 2, 8, 8, 8, requires_grad=True)
    with SavedBytes() as s:
        y = conv(x)
        assert s.total == x.numel() * 4 + conv.weight.numel() * 4
        y.sum().backward()
        del y
    assert s.peak == x.numel() * 4 + conv.weight.numel() * 4 and s.total == 0


def test_step_total_is_the_parts_weighted_by_their_runs_and_each_option_counts(completion_demo_nets):
    nets = tiny_nets(completion_demo_nets)
    base = completion_step_cost(_meta_task(nets))
    parts = {p["part"]: p for p in base["parts"]}
    assert list(parts) == ["critic fakes", "critic scores", "critic penalty", "generator"]
    assert base["flops"] == sum(p["flops"] * p["runs"] for p in parts.values())
    assert all(p["flops"] > 0 for p in parts.values())
    # the critic's fakes are a generator forward without a graph: counted alone, the same
    with torch.device(META):
        x = torch.zeros(1, 1, 8, 8, 8)
    task = _meta_task(nets)
    with CostCounter() as c:
        task.generator(x)
    assert parts["critic fakes"]["flops"] == c.flops and parts["critic fakes"]["saved_bytes"] == 0
    # lazy regularisation: the penalty's share falls by N, the rest is unchanged
    lazy = completion_step_cost(_meta_task(nets, gp_every=2))
    assert lazy["flops"] == base["flops"] - parts["critic penalty"]["flops"] / 2
    # two critic updates: the critic parts twice
    two = completion_step_cost(_meta_task(nets, critic_steps=2))
    assert two["flops"] == base["flops"] + sum(parts[p]["flops"] for p in ("critic fakes", "critic scores", "critic penalty"))
    # one critic pass over real + fake: the same FLOPs, fewer launches
    cat = completion_step_cost(_meta_task(nets, critic_concat=True))
    cat_parts = {p["part"]: p for p in cat["parts"]}
    assert cat["flops"] == base["flops"]
    assert cat_parts["critic scores"]["ops"] < parts["critic scores"]["ops"]
    # without the critic: the generator update alone, cheaper than with the critic's term
    plain = completion_step_cost(_meta_task(nets, adversarial=False))
    assert [p["part"] for p in plain["parts"]] == ["generator"]
    assert plain["flops"] < parts["generator"]["flops"]


def test_bf16_penalty_keeps_the_flops_and_saves_fewer_bytes(completion_demo_nets):
    nets = tiny_nets(completion_demo_nets)
    base = {p["part"]: p for p in completion_step_cost(_meta_task(nets))["parts"]}
    bf16 = {p["part"]: p for p in completion_step_cost(_meta_task(nets, gp_precision="bf16"))["parts"]}
    assert all(bf16[k]["flops"] == base[k]["flops"] for k in base)
    assert bf16["critic penalty"]["saved_bytes"] < base["critic penalty"]["saved_bytes"]
    assert all(bf16[k]["saved_bytes"] == base[k]["saved_bytes"] for k in base if k != "critic penalty")


def test_step_cost_refuses_a_task_with_real_weights(completion_demo_nets):
    with pytest.raises(ValueError, match="meta device"):
        completion_step_cost(CompletionTask(nets=tiny_nets(completion_demo_nets)))


def test_paper_scale_step_agrees_with_the_earlier_count(completion_paper_nets):
    cost = completion_step_cost(_meta_task(completion_paper_nets))
    parts = {p["part"]: p["flops"] / 1e12 for p in cost["parts"]}
    assert cost["flops"] / 1e12 == pytest.approx(3.4, rel=0.05)
    for part, want in (("critic fakes", 0.27), ("critic scores", 0.89), ("critic penalty", 0.94), ("generator", 1.31)):
        assert parts[part] == pytest.approx(want, rel=0.05), part
    # activation memory per sample: a paper step keeps gigabytes for backward (the GPU measured 3.4 GiB/sample peak)
    assert 1 * 2**30 < cost["saved_bytes"] < 3.4 * 2**30


def test_gpu_rows_gain_their_fraction_of_the_gpus_peak(tmp_path):
    from benchmarks.common import GPU_CMD, row
    from benchmarks.run import gpu_section

    rows = [row("completion train step, paper 64^3->256^3, batch 12, fp32", GPU_CMD, 2.0, None, unit="s/step"),
            row("completion train step, paper 64^3->256^3, batch 12, bf16-mixed", GPU_CMD, 2.0, 2.0, unit="s/step",
                baseline_name="fp32"),
            row("quality feature table", GPU_CMD, 2.0, None, unit="s")]
    path = tmp_path / "gpu_rows.json"
    path.write_text(json.dumps({"date": "d", "gpu": "NVIDIA H200", "cpu": "x", "cores": 16, "torch": "t",
                                "minutes": 1.0, "rows": rows, "failures": []}))
    text = gpu_section(path, tflop_per_sample=3.4)
    # 12 / 2.0 s = 6 samples/s x 3.4 TFLOP = 20.4 TFLOP/s: 4.1% of 494.5 (TF32), 30% of 67 (FP32); 2.1% of 989.5 (BF16)
    assert "20.4 TFLOP/s = 4.1% of the dense TF32 peak (494.5 TFLOP/s" in text and "30% of the FP32 peak (67)" in text
    assert "20.4 TFLOP/s = 2.1% of the dense BF16 peak (989.5 TFLOP/s)" in text
    assert text.count("TFLOP/s =") == 2  # the quality row has no step to count
