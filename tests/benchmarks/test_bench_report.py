"""``benchmarks.run``'s GPU rows: measured by ``--gpu`` on a CUDA machine, shown by a later CPU run."""
from __future__ import annotations

import json

import pytest
import torch

from benchmarks.common import GPU_CMD, row
from benchmarks.run import gpu_section, run_gpu
from tests.helpers.paths import REPO


def test_gpu_section_shows_the_rows_and_the_machine_they_were_measured_on(tmp_path):
    path = tmp_path / "gpu_rows.json"
    assert gpu_section(path) == ""  # nothing measured: no section
    rows = [row("completion train step, paper, bf16-mixed", GPU_CMD, 0.5, 1.0, unit="s/step", baseline_name="fp32",
                device="cpu")]
    path.write_text(json.dumps({"date": "2026-11-26", "gpu": "NVIDIA H200", "cpu": "x86", "cores": 16,
                                "torch": "2.11.0", "minutes": 3.0, "rows": rows,
                                "failures": [["bench_quality", "RuntimeError: EGL"]]}))
    text = gpu_section(path)
    assert "NVIDIA H200" in text and "2026-11-26" in text and "torch 2.11.0" in text
    assert "| completion train step, paper, bf16-mixed |" in text and "2.00x" in text and "fp32: 1 s/step" in text
    assert "`bench_quality`: RuntimeError: EGL" in text


@pytest.mark.skipif(torch.cuda.is_available(), reason="checks the refusal on a machine without CUDA")
def test_gpu_run_refuses_without_cuda(tmp_path):
    with pytest.raises(SystemExit, match="no CUDA device"):
        run_gpu([], tmp_path / "rows.json")
    assert not (tmp_path / "rows.json").exists()


def test_configuration_page_agrees_with_the_measured_gpu_rows():
    """docs/configuration.md names the GPU of benchmarks/gpu_rows.json, and never says none was measured."""
    page = " ".join((REPO / "docs" / "configuration.md").read_text().split())
    measured = json.loads((REPO / "benchmarks" / "gpu_rows.json").read_text())
    assert measured["rows"], "benchmarks/gpu_rows.json holds no row"
    assert "not measured" not in page and "no GPU was lent" not in page
    assert measured["gpu"] in page and "BENCHMARKS.md" in page
