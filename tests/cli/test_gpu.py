"""The three tasks on a CUDA GPU (marker ``gpu``: skipped without CUDA, run with ``pytest -m gpu``).

Each task trains two batches on the GPU in bf16-mixed (``trainer=gpu``), and its checkpoint is
evaluated on the GPU in fp32 and on the CPU: the test metrics must agree, so nothing in the test
path depends on the device (a metric state left on the wrong device, a CPU-only op, a dtype kept
from bf16). The quality features are checked the same way with the measures on the GPU.
"""
from __future__ import annotations

import math
from pathlib import Path

import pytest
import torch
from omegaconf import open_dict

from lit3d.cli.evaluate import evaluate
from lit3d.cli.train import train
from tests.helpers.ddp import CASES, COMMON

pytestmark = pytest.mark.gpu


@pytest.fixture
def no_tf32():
    """fp32 convolutions without TF32, so GPU and CPU metrics agree to float32 rounding."""
    before = torch.backends.cudnn.allow_tf32, torch.backends.cuda.matmul.allow_tf32
    torch.backends.cudnn.allow_tf32 = torch.backends.cuda.matmul.allow_tf32 = False
    yield
    torch.backends.cudnn.allow_tf32, torch.backends.cuda.matmul.allow_tf32 = before


def _evaluate(compose_cfg, ckpt: Path, trainer: list[str], out: Path) -> dict[str, float]:
    cfg = compose_cfg([f"ckpt_path={ckpt}", *trainer, "n_figures=0", "seed=0"], config_name="eval")
    with open_dict(cfg):
        cfg.paths.output_dir = str(out)
    return evaluate(cfg)


def _close(a, b, tol: float = 1e-3) -> bool:
    if a is None or b is None or a != a or b != b:
        return (a is None or a != a) and (b is None or b != b)
    return abs(a - b) <= tol * max(1.0, abs(a))


@pytest.mark.parametrize("task", sorted(CASES))
def test_trains_on_gpu_and_evaluates_as_on_cpu(task, compose_cfg, tmp_path, no_tf32):
    cfg = compose_cfg([*CASES[task], *COMMON, "trainer=gpu"], data_dir=tmp_path / "data")
    train(cfg)
    ckpt = Path(cfg.paths.output_dir) / "checkpoints" / "last.ckpt"
    state = torch.load(ckpt, map_location="cpu", weights_only=False)["state_dict"]
    assert all(torch.isfinite(v).all() for v in state.values() if v.is_floating_point()), "bf16 training left NaN"
    gpu = _evaluate(compose_cfg, ckpt, ["trainer=gpu", "trainer.precision=32-true"], tmp_path / "eval_gpu")
    cpu = _evaluate(compose_cfg, ckpt, ["trainer=cpu"], tmp_path / "eval_cpu")
    keys = sorted(k for k in cpu if k.startswith("test/") and "seconds" not in k)
    assert keys and keys == sorted(k for k in gpu if k.startswith("test/") and "seconds" not in k)
    differ = {k: (gpu[k], cpu[k]) for k in keys if not _close(gpu[k], cpu[k])}
    assert not differ, differ


def test_quality_features_on_gpu_match_cpu():
    """Mask-SSIM and every other measure computed on the GPU equal the CPU's (same renders)."""
    import trimesh

    from lit3d.features.table import FeatureConfig, feature_table
    from lit3d.render.gbuffer import RenderConfig

    ref = trimesh.creation.icosphere(subdivisions=3)
    dist = ref.copy()
    dist.vertices = dist.vertices * [1.15, 1.0, 1.0]  # a stretched sphere
    cfg = FeatureConfig(render=RenderConfig(size=128), styles=("toon", "jade"))
    on_gpu = feature_table(ref, dist, cfg, device="cuda").features
    on_cpu = feature_table(ref, dist, cfg).features
    assert on_gpu.keys() == on_cpu.keys() and len(on_cpu) > 10
    differ = {k: (on_gpu[k], on_cpu[k]) for k in on_cpu
              if not (math.isnan(on_cpu[k]) and math.isnan(on_gpu[k])) and abs(on_gpu[k] - on_cpu[k]) > 1e-3}
    assert not differ, differ


def test_paper_scale_step_runs_in_bf16_on_gpu():
    """One paper-scale (64^3 -> 256^3) training step per variant of the GPU benchmark, no failure row."""
    from benchmarks.bench_completion import GPU_VARIANTS, paper_gpu_rows

    rows = paper_gpu_rows(steps=2, warmup=1, variants=GPU_VARIANTS[:2])
    assert [r["ours"] is not None for r in rows] == [True, True], [r["note"] for r in rows]
