"""Meta-device summaries: parameter counts, shapes and activation bytes without real memory."""
from __future__ import annotations

import torch
import torch.nn as nn

from lit3d.completion.nets import build_completion_nets
from lit3d.completion.summary import summarize_completion
from lit3d.utils.summary import format_summary_table, summarize


def test_summarize_small_model_matches_real_counts_and_bytes():
    torch.manual_seed(0)
    model = nn.Sequential(nn.Conv3d(1, 4, 3, padding=1), nn.ReLU(), nn.MaxPool3d(2), nn.Flatten(), nn.Linear(4 * 8**3, 5))
    s = summarize(model, [(3, 1, 16, 16, 16)])
    assert s["params"] == sum(p.numel() for p in model.parameters())
    assert s["output_shape"] == (3, 5)
    # per sample: conv 4*16^3, relu 4*16^3, pool 4*8^3, flatten 4*8^3, linear 5 floats
    floats = 2 * 4 * 16**3 + 2 * 4 * 8**3 + 5
    assert s["activation_bytes_per_sample"] == 4 * floats
    assert all(p.device.type == "cpu" for p in model.parameters())  # the original is untouched
    # the real model gives the same output shape
    assert model(torch.zeros(3, 1, 16, 16, 16)).shape == (3, 5)
    half = summarize(model, [(3, 1, 16, 16, 16)], dtype=torch.bfloat16)
    assert half["activation_bytes_per_sample"] == 2 * floats


def test_summarize_skips_inplace_and_handles_tuple_outputs():
    class Two(nn.Module):
        def __init__(self):
            super().__init__()
            self.a = nn.Linear(3, 2)
            self.act = nn.ReLU(inplace=True)

        def forward(self, x):
            y = self.act(self.a(x))
            return y, y.sum(1)

    s = summarize(Two(), [(4, 3)])
    assert s["output_shape"] == [(4, 2), (4,)]
    assert s["activation_bytes_per_sample"] == 2 * 4  # Linear output only


def test_paper_generator_summary_on_meta_device(completion_paper_nets):
    rows = {r["component"]: r for r in summarize_completion(completion_paper_nets)}
    g = rows["generator"]
    assert g["input"] == (1, 1, 64, 64, 64) and g["output"] == (1, 1, 256, 256, 256)
    assert rows["generator stage 1"]["output"] == (1, 1, 64, 64, 64)
    assert rows["generator stage 2"]["input"] == (1, 2, 64, 64, 64)
    assert rows["generator stage 3"]["input"] == (1, 3, 64, 64, 64)
    assert rows["generator stage 3"]["output"] == (1, 1, 256, 256, 256)
    assert rows["critic"]["output"] == (1,)
    assert rows["classifier"]["output"] == (1, 4)
    # final 1-channel 256^3 fp32 map alone is 64 MiB per sample
    assert g["activation_bytes_per_sample"] > 64 * 2**20
    # parameter counts agree with the nets built on meta
    with torch.device("meta"):
        nets = build_completion_nets(completion_paper_nets)
    for name in ("generator", "critic", "classifier"):
        assert rows[name]["params"] == sum(p.numel() for p in nets[name].parameters())
    stages = sum(rows[f"generator stage {i}"]["params"] for i in (1, 2, 3))
    assert stages == g["params"]
    # FC 512*4^3 -> 1000 and back, selector 2 x (1000^2 + 1000)
    assert rows["  selector 1 (n=1000, K=100)"]["params"] == 2 * (1000 * 1000 + 1000)
    table = format_summary_table(list(rows.values()))
    assert "1x1x256x256x256" in table and "generator stage 3" in table
    assert f"{g['params']:,}" in table


def test_summary_works_inside_meta_context(completion_demo_nets):
    # lit3d-summary calls summary_rows inside `with torch.device("meta")`
    with torch.device("meta"):
        rows = summarize_completion({**completion_demo_nets, "stages": 2, "selector": False})
    names = [r["component"] for r in rows]
    assert names[:2] == ["generator stage 1", "generator stage 2"]
    assert not any("selector" in n for n in names)
    assert {r["component"]: r for r in rows}["generator"]["output"] == (1, 1, 64, 64, 64)


def test_the_canonical_summaries_are_options_of_lit3d_summary(capsys):
    """``--pooled`` and ``--over-runs`` take the argparse path (their own pages and errors); anything else is
    the Hydra ``lit3d-summary`` of a config."""
    import pytest

    from lit3d.cli import summary_canonical

    assert summary_canonical.main(["experiment=completion_demo", "task.nets.k=50"]) is None
    for option in summary_canonical.OPTIONS:
        with pytest.raises(SystemExit) as info:
            summary_canonical.main([option, "DIR", "--help"])
        assert info.value.code == 0 and f"{option} " in capsys.readouterr().out
    with pytest.raises(SystemExit) as info:
        summary_canonical.main(["--pooled", "--over-runs", "x", "--out", "y"])
    assert info.value.code == 2 and "unrecognized arguments: --over-runs x" in capsys.readouterr().err
