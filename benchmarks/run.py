"""``make bench``: run every ``benchmarks/bench_*.py`` and rewrite BENCHMARKS.md.

Each module has ``run() -> list[dict]`` (rows from ``benchmarks.common.row``). A module
that fails is reported in the file with its error instead of silently vanishing.

    python -m benchmarks.run                 # everything, rewrites BENCHMARKS.md
    python -m benchmarks.run quality canon   # only matching modules, printed (add --write to save)
"""
from __future__ import annotations

import datetime
import importlib
import os
import pkgutil
import sys
import time
import traceback
from pathlib import Path

import torch

import benchmarks
from benchmarks.common import cpu_model, default_threads, load_avg
from lit3d.utils.tables import markdown_table

OUT = Path(__file__).resolve().parents[1] / "BENCHMARKS.md"


def _num(v, unit: str) -> str:
    if v is None:
        return "–"
    return f"{v:.4g} {unit}".strip()


def _load_line(before: tuple | None, after: tuple | None, peak: float | None) -> str:
    if before is None:
        return ""
    cores = os.cpu_count() or 1
    busy = max(before[0], after[0] if after else 0, peak or 0)
    text = (f"Load average (1/5/15 min) at the start {before[0]:.1f}/{before[1]:.1f}/{before[2]:.1f}, at the end "
            f"{after[0]:.1f}/{after[1]:.1f}/{after[2]:.1f}, highest 1-min value seen between rows {peak:.1f} "
            f"on {cores} cores.")
    if busy > cores + 0.5:  # the benchmarks' own threads load every core: only more than that is other work
        text += (" **The machine was shared with other jobs during this run**: times are those of a contended "
                 "CPU (each row's machine column gives the load when it was measured); rows run with one "
                 "intra-op thread are the least affected.")
    return text + "\n"


def main(argv: list[str] | None = None) -> str:
    argv = list(sys.argv[1:] if argv is None else argv)
    write = "--write" in argv
    selected = [a for a in argv if not a.startswith("--")]
    names = sorted(m.name for m in pkgutil.iter_modules(benchmarks.__path__) if m.name.startswith("bench_"))
    if selected:
        names = [n for n in names if any(s in n for s in selected)]
    else:
        write = True
    rows, failures, durations = [], [], []
    before, peak = (os.getloadavg() if hasattr(os, "getloadavg") else None), load_avg()
    t_start = time.perf_counter()
    for name in names:
        print(f"[bench] {name} ...", flush=True)
        t0 = time.perf_counter()
        try:
            rows += importlib.import_module(f"benchmarks.{name}").run()
        except Exception as exc:  # keep the other rows
            failures.append((name, f"{type(exc).__name__}: {exc}"))
            traceback.print_exc()
        durations.append((name, time.perf_counter() - t0))
        la = load_avg()
        peak = max(peak or 0, la or 0)
        print(f"[bench] {name}: {durations[-1][1]:.0f} s (load {la})", flush=True)
    total = time.perf_counter() - t_start
    after = os.getloadavg() if hasattr(os, "getloadavg") else None
    table = markdown_table(
        ["benchmark", "machine", "ours", "baseline (same run)", "ratio", "note", "command"],
        [[r["name"], r["machine"], _num(r["ours"], r["unit"]),
          (f"{r['baseline_name']}: " if r.get("baseline_name") else "") + _num(r["baseline"], r["unit"]),
          "–" if r["ratio"] is None else f"{r['ratio']:.2f}x", r["note"], f"`{r['command']}`"] for r in rows],
    )
    gpu = torch.cuda.is_available()
    gpu_note = ("" if gpu else
                "\n**No NVIDIA GPU on this machine: the paper-scale GPU rows (completion at 64^3 -> 256^3, batch 3, "
                "bf16-mixed vs fp32, channels_last_3d, torch.compile; the quality table with measures on the GPU) "
                "were not measured.** Their code runs when CUDA is available "
                "(`benchmarks/bench_completion.py::paper_gpu_rows`, `benchmarks/bench_quality.py`); on CPU they "
                "appear below as rows without figures.\n")
    text = (f"# Benchmarks\n\nWritten by `make bench` (`.venv/bin/python -m benchmarks.run`) on "
            f"{datetime.date.today()} in {total / 60:.1f} min — CPU {cpu_model()}, {os.cpu_count()} cores, "
            f"torch {torch.__version__} (default {default_threads()} intra-op threads)"
            f"{', GPU ' + torch.cuda.get_device_name(0) if gpu else ''}.\n\n"
            "Times are medians of several runs after a warm-up; every baseline is measured in the same run, on the "
            "same machine and thread count as our figure. Ratio = baseline / ours for times (>1: ours is faster), "
            "ours / baseline for rates (samples/s). Each row's note gives its target where the issue sets one "
            "(met, or MISSED by how much).\n"
            f"{_load_line(before, after, peak)}{gpu_note}\n{table}\n\n"
            "Per module: " + ", ".join(f"`{n}` {d:.0f} s" for n, d in durations) + ".\n")
    if failures:
        text += "\n## Benchmarks that failed\n\n" + "\n".join(f"- `{n}`: {e}" for n, e in failures) + "\n"
    if write:
        OUT.write_text(text)
    print(text)
    return text


if __name__ == "__main__":
    main()
