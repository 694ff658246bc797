"""``benchmarks/profile_step.py`` (``make bench-gpu``'s profile): runs end to end on a tiny config on the CPU."""
from __future__ import annotations

import pytest

from benchmarks.profile_step import kernel_busy_us, main


def test_kernel_busy_time_is_the_union_of_the_kernels_intervals():
    assert kernel_busy_us([(0, 10), (5, 12), (20, 25), (21, 22)]) == 17
    assert kernel_busy_us([]) == 0


@pytest.mark.usefixtures("one_torch_thread")
def test_profile_script_writes_the_table_on_a_tiny_config(tmp_path):
    out = tmp_path / "profile.md"
    main(["--tiny", "--out", str(out), "--variants", "default,gp_bf16"])
    text = out.read_text()
    assert "## default, batch 2" in text and "Step wall time" in text and "Top 25 ops by self CPU time" in text
    assert "aten::convolution" in text
    # the step switches, one profile each, in one call; a summary row each
    assert "## gp_bf16, batch 2" in text and "| gp_bf16 | task.adversarial.gp_precision=bf16 | 2 |" in text
    assert "Failed" not in text


def test_profile_variants_are_the_config_switches():
    from benchmarks.profile_step import VARIANTS, _variants
    from lit3d.runtime.compose import compose_config

    assert list(_variants("every")) == list(VARIANTS)
    with pytest.raises(SystemExit, match="unknown"):
        _variants("default,turbo")
    for overrides in VARIANTS.values():  # each override names a key of the task's config
        compose_config("train", ["experiment=completion_paper", *overrides])
