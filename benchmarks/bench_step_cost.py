"""The cost of a training step: FLOPs per sample, kernel-like ops and activation memory, counted on the meta device.

Rows (no timing: the count depends on the config alone, not on the machine):
- completion (64^3 -> 256^3, ``experiment=completion_paper``) per part of the manual-optimisation step
  (:mod:`lit3d.completion.step_cost`), then with each option that cuts the step (``task.adversarial.gp_every=4``,
  ``task.adversarial.critic_concat=true``, ``task.adversarial.gp_precision=bf16``, then all three; ratio = default / option,
  in FLOPs; the
  note gives the bytes saved for backward, which bf16 cuts), and the demo scale with the critic on.
  ``task.compile_step`` has no row: it changes how the ops run (fusion, launches), not the count;
- canonical (``experiment=canonical_paper``) at 128^2 and 500^2 (:mod:`lit3d.canonical.step_cost`).

FLOPs are PyTorch's formulas (``torch.utils.flop_counter``: convolutions, matmuls, attention), a multiply-add
counting 2. :func:`peak_fraction` turns a measured samples/s into a fraction of a GPU's dense peak (used by
``benchmarks.run`` for the GPU rows).

    python -m benchmarks.bench_step_cost          # prints the rows
"""
from __future__ import annotations

import functools
import re

import torch

from benchmarks.common import row
from lit3d.canonical.step_cost import canonical_step_cost
from lit3d.runtime.build import build_task
from lit3d.runtime.compose import compose_config
from lit3d.completion.step_cost import completion_step_cost
from lit3d.utils.tables import markdown_table

CMD = "python -m benchmarks.bench_step_cost"
REFERENCE_TFLOP = 3.4  # the earlier count of the paper-scale step (FlopCounterMode's formulas, one sample)
WITH_CRITIC = ["task.adversarial.use=true", "task.adversarial.start_epoch=0"]

# Dense (no sparsity) peaks, TFLOP/s, from NVIDIA's data sheets (their tensor-core figures halved: those are
# quoted with 2:4 sparsity). fp32 training runs its convolutions in TF32 on the tensor cores by default
# (torch.backends.cudnn.allow_tf32 = True).
GPU_PEAKS = {
    "H200": {"fp32": 67.0, "tf32": 494.5, "bf16": 989.5},
    "H100": {"fp32": 67.0, "tf32": 494.5, "bf16": 989.5},  # SXM
    "A100": {"fp32": 19.5, "tf32": 156.0, "bf16": 312.0},
}


def _task(experiment: str, overrides=()):
    cfg = compose_config("train", [f"experiment={experiment}", *overrides])
    with torch.device("meta"):
        return build_task(cfg.task)


def completion_cost(experiment: str = "completion_paper", overrides=(), critic: bool = True) -> dict:
    """:func:`lit3d.completion.step_cost.completion_step_cost` of the composed task (``critic``: forced on from
    the first epoch; False: as the experiment configures it)."""
    return completion_step_cost(_task(experiment, [*(WITH_CRITIC if critic else []), *overrides]))


@functools.lru_cache(maxsize=1)
def paper_tflop_per_sample() -> float:
    """TFLOP per sample of the default paper-scale completion step (the GPU rows' configuration)."""
    return completion_cost()["flops"] / 1e12


def peak_fraction(gpu_name: str, samples_per_s: float, tflop_per_sample: float, precision: str) -> str:
    """``"19.6 TFLOP/s = 4.0% of the H200's dense TF32 peak (494.5 TFLOP/s), 29% of its FP32 peak (67)"``;
    ``precision``: "fp32" (convs in TF32) or "bf16"; '' for a GPU without a listed peak."""
    peaks = next((v for k, v in GPU_PEAKS.items() if k in gpu_name), None)
    if peaks is None:
        return ""
    rate = samples_per_s * tflop_per_sample
    if precision == "bf16":
        return f"{rate:.1f} TFLOP/s = {100 * rate / peaks['bf16']:.1f}% of the dense BF16 peak ({peaks['bf16']:g} TFLOP/s)"
    return (f"{rate:.1f} TFLOP/s = {100 * rate / peaks['tf32']:.1f}% of the dense TF32 peak ({peaks['tf32']:g} TFLOP/s, "
            f"cuDNN's default for fp32 convs), {100 * rate / peaks['fp32']:.0f}% of the FP32 peak ({peaks['fp32']:g})")


def gpu_row_fraction(r: dict, gpu_name: str, tflop_per_sample: float) -> str:
    """:func:`peak_fraction` of a paper-scale completion GPU step row (name with ``batch N``, unit s/step), else ''."""
    m = re.search(r"batch (\d+)", r.get("name", ""))
    if not (r.get("name", "").startswith("completion train step, paper") and m and r.get("ours")
            and r.get("unit") == "s/step"):
        return ""
    precision = "bf16" if "bf16" in r["name"] else "fp32"
    return peak_fraction(gpu_name, int(m.group(1)) / r["ours"], tflop_per_sample, precision)


def _parts_note(cost: dict) -> str:
    parts = "; ".join(f"{p['part']} {p['flops'] / 1e12:.3g}" + (f" x {p['runs']:g}" if p["runs"] != 1 else "")
                      for p in cost["parts"])
    return (f"TFLOP/sample per part: {parts}; {cost['ops']:.0f} kernel-like aten ops per step; activation memory "
            f"(saved for backward, peak of the step) {cost['saved_bytes'] / 2**20:.0f} MiB/sample")


# the switches that change the count (task.compile_step does not: the count is of the eager step's ops, and
# compiling changes how they run, not how many FLOPs they take), one row each, then all of them together
OPTIONS = (
    ("task.adversarial.gp_every=4 (lazy gradient penalty)", ["task.adversarial.gp_every=4"]),
    ("task.adversarial.critic_concat=true (one critic pass over real + fake)", ["task.adversarial.critic_concat=true"]),
    ("task.adversarial.gp_precision=bf16 (the penalty's critic pass in bf16: fewer bytes saved for backward, the same FLOPs)",
     ["task.adversarial.gp_precision=bf16"]),
    ("every option on (gp_every=4, critic_concat, gp_precision=bf16)",
     ["task.adversarial.gp_every=4", "task.adversarial.critic_concat=true", "task.adversarial.gp_precision=bf16"]),
)


def _mib(cost: dict, part: str | None = None) -> str:
    """Saved-for-backward MiB per sample of the step (its peak) or of one ``part``."""
    b = cost["saved_bytes"] if part is None else next(p["saved_bytes"] for p in cost["parts"] if p["part"] == part)
    return f"{b / 2**20:.0f}"


def completion_rows() -> list[dict]:
    base = completion_cost()
    total = base["flops"] / 1e12
    off = 100 * (total / REFERENCE_TFLOP - 1)
    rows = [row("completion train step FLOPs, paper 64^3->256^3, 1 critic update + 1 generator update", CMD, total, None,
                unit="TFLOP/sample",
                note=_parts_note(base) + f"; the earlier count {REFERENCE_TFLOP:g} TFLOP: {off:+.1f}% (within 5%: "
                     f"{'yes' if abs(off) <= 5 else 'NO'}); optimiser and element-wise work not counted")]
    for label, ov in OPTIONS:
        c = completion_cost(overrides=ov)
        rows.append(row(f"completion train step FLOPs, paper, {label}", CMD, c["flops"] / 1e12, total,
                        unit="TFLOP/sample", baseline_name="default step",
                        note=_parts_note(c) + f"; kernel-like ops {c['ops']:.0f} vs {base['ops']:.0f} by default; "
                             f"saved for backward: the step's peak {_mib(c)} vs {_mib(base)} MiB/sample, the penalty's "
                             f"{_mib(c, 'critic penalty')} vs {_mib(base, 'critic penalty')}"))
    demo = completion_cost("completion_demo")
    plain = completion_cost("completion_demo", critic=False)
    rows.append(row("completion train step FLOPs, demo 16^3->64^3, critic on", CMD, demo["flops"] / 1e12, None,
                    unit="TFLOP/sample",
                    note=_parts_note(demo) + "; experiment=completion_demo as configured trains without the critic "
                         f"(task.adversarial.use=false): {plain['flops'] / 1e12:.3g} TFLOP/sample, {plain['ops']:.0f} ops, "
                         f"{plain['saved_bytes'] / 2**20:.0f} MiB/sample"))
    return rows


def canonical_rows() -> list[dict]:
    rows = []
    for size in (128, 500):
        task = _task("canonical_paper", [f"task.net.image_size={size}", f"data.image_size={size}",
                                         "evaluation.retrieval=null"])
        c = canonical_step_cost(task, size)
        rows.append(row(f"canonical train step FLOPs, paper-size CanonicalNet, {size}^2", CMD, c["flops"] / 1e12, None,
                        unit="TFLOP/image",
                        note=f"net forward + depth/mask (+ warp) loss + backward; {c['ops']} kernel-like aten ops per "
                             f"step; activation memory (saved for backward) {c['saved_bytes'] / 2**20:.0f} MiB/image"))
    return rows


def run() -> list[dict]:
    return completion_rows() + canonical_rows()


if __name__ == "__main__":
    print(markdown_table(["benchmark", "ours", "baseline", "note"],
                         [[r["name"], f"{r['ours']:.4g} {r['unit']}",
                           "–" if r["baseline"] is None else f"{r['baseline_name']}: {r['baseline']:.4g}", r["note"]]
                          for r in run()]))
