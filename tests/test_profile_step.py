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
    main(["--tiny", "--out", str(out)])
    text = out.read_text()
    assert "## Batch 2" in text and "Step wall time" in text and "Top 25 ops by self CPU time" in text
    assert "aten::convolution" in text
