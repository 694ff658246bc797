"""``make bench``: run every ``benchmarks/bench_*.py`` and rewrite BENCHMARKS.md.

Each module has ``run() -> list[dict]`` (rows from ``benchmarks.common.row``). A module
that fails is reported in the file with its error instead of silently vanishing.

    python -m benchmarks.run                 # everything, rewrites BENCHMARKS.md
    python -m benchmarks.run quality canon   # only matching modules, printed (add --write to save)
    python -m benchmarks.run --gpu [--out F] # only the modules' gpu_rows(), on a CUDA machine: writes F
                                             # (default benchmarks/gpu_rows.json), which a later CPU run
                                             # copies into BENCHMARKS.md as its GPU section
"""
from __future__ import annotations

import datetime
import importlib
import json
import os
import pkgutil
import sys
import time
import traceback
from pathlib import Path

import torch

import benchmarks
from benchmarks.bench_step_cost import gpu_row_fraction, paper_tflop_per_sample
from benchmarks.common import GPU_CMD, cpu_model, default_threads, load_avg
from lit3d.utils.tables import markdown_table

OUT = Path(__file__).resolve().parents[1] / "BENCHMARKS.md"
GPU_ROWS = Path(__file__).resolve().with_name("gpu_rows.json")  # written by --gpu on a CUDA machine


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


def _table(rows: list[dict]) -> str:
    return markdown_table(
        ["benchmark", "machine", "ours", "baseline (same run)", "ratio", "note", "command"],
        [[r["name"], r["machine"], _num(r["ours"], r["unit"]),
          (f"{r['baseline_name']}: " if r.get("baseline_name") else "") + _num(r["baseline"], r["unit"]),
          "–" if r["ratio"] is None else f"{r['ratio']:.2f}x", r["note"], f"`{r['command']}`"] for r in rows],
    )


def _modules(selected: list[str]) -> list[str]:
    """The ``bench_*`` modules, all in name order, or those matching ``selected`` in the order given."""
    names = sorted(m.name for m in pkgutil.iter_modules(benchmarks.__path__) if m.name.startswith("bench_"))
    if not selected:
        return names
    return [n for s in selected for n in names if s in n]


def run_gpu(selected: list[str], out: Path = GPU_ROWS) -> dict:
    """Run each module's ``gpu_rows()`` (CUDA only) and write them, with the machine, to ``out`` (JSON)."""
    if not torch.cuda.is_available():
        raise SystemExit("error: benchmarks.run --gpu: no CUDA device on this machine")
    rows, failures, t0 = [], [], time.perf_counter()
    data = {"date": str(datetime.date.today()), "gpu": torch.cuda.get_device_name(0), "cpu": cpu_model(),
            "cores": os.cpu_count(), "torch": torch.__version__, "rows": rows, "failures": failures}
    for name in _modules(selected):
        print(f"[bench-gpu] {name} ...", flush=True)
        try:
            module = importlib.import_module(f"benchmarks.{name}")
            rows += module.gpu_rows() if hasattr(module, "gpu_rows") else []
        except Exception as exc:  # keep the other rows
            failures.append((name, f"{type(exc).__name__}: {exc}"))
            traceback.print_exc()
        data["minutes"] = (time.perf_counter() - t0) / 60
        out.write_text(json.dumps(data, indent=1) + "\n")  # after each module: a run cut short keeps its rows
    print(_table(rows))
    return data


def _with_peak_fraction(rows: list[dict], gpu: str, tflop_per_sample: float | None) -> list[dict]:
    """The paper-scale completion step rows with their fraction of the GPU's dense peak added to the note
    (measured samples/s x the step's FLOPs per sample, :mod:`benchmarks.bench_step_cost`)."""
    if tflop_per_sample is None:
        try:
            tflop_per_sample = paper_tflop_per_sample()
        except Exception as exc:  # the section still shows the measured rows
            print(f"[bench] no FLOP count for the GPU rows: {type(exc).__name__}: {exc}", flush=True)
            return rows
    out = []
    for r in rows:
        frac = gpu_row_fraction(r, gpu, tflop_per_sample)
        out.append({**r, "note": r["note"] + f"; at {tflop_per_sample:.2f} TFLOP/sample: {frac}"} if frac else r)
    return out


def gpu_section(path: Path = GPU_ROWS, tflop_per_sample: float | None = None) -> str:
    """BENCHMARKS.md's section of GPU rows measured earlier by ``--gpu`` ('' when there are none); the
    completion step rows gain their fraction of the GPU's peak (``tflop_per_sample``: the paper step's
    FLOPs per sample, counted when None)."""
    if not path.exists():
        return ""
    data = json.loads(path.read_text())
    data["rows"] = _with_peak_fraction(data["rows"], data["gpu"], tflop_per_sample)
    text = (f"\n## GPU rows\n\nMeasured by `make bench-gpu` (`python -m benchmarks.run --gpu`) on {data['date']} in "
            f"{data['minutes']:.1f} min on an {data['gpu']} (CPU {data['cpu']}, {data['cores']} cores), torch "
            f"{data['torch']}; each baseline in the same run on that machine. Copied from `benchmarks/gpu_rows.json`, "
            "not measured by this run." + (f" {data['note']}" if data.get("note") else "") + "\n\n"
            + _table(data["rows"]) + "\n")
    if data["failures"]:
        text += "\nFailed there: " + "; ".join(f"`{n}`: {e}" for n, e in data["failures"]) + "\n"
    return text


def main(argv: list[str] | None = None) -> str:
    argv = list(sys.argv[1:] if argv is None else argv)
    write = "--write" in argv
    out = Path(argv[argv.index("--out") + 1]) if "--out" in argv else GPU_ROWS
    selected = [a for a in argv if not a.startswith("--") and a != str(out)]
    if "--gpu" in argv:
        return json.dumps(run_gpu(selected, out))
    names = _modules(selected)
    write = write or not selected
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
    gpu = torch.cuda.is_available()
    gpu_text = "" if gpu else gpu_section()
    if gpu_text:  # the GPU rows come from the section, not from this run's placeholders
        rows = [r for r in rows if not (r["command"] == GPU_CMD and r["ours"] is None)]
    table = _table(rows)
    gpu_note = ("" if gpu else
                "\n**No NVIDIA GPU on this machine**: the paper-scale GPU rows (completion at 64^3 -> 256^3, batch 3, "
                "bf16-mixed vs fp32, channels_last_3d, torch.compile; the quality table with measures on the GPU) "
                + ("are those of the section 'GPU rows' at the end, measured on a GPU by `make bench-gpu`.\n"
                   if gpu_text else "were not measured; on CPU they appear below as rows without figures.\n"))
    text = (f"# Benchmarks\n\nWritten by `make bench` (`.venv/bin/python -m benchmarks.run`) on "
            f"{datetime.date.today()} in {total / 60:.1f} min — CPU {cpu_model()}, {os.cpu_count()} cores, "
            f"torch {torch.__version__} (default {default_threads()} intra-op threads)"
            f"{', GPU ' + torch.cuda.get_device_name(0) if gpu else ''}.\n\n"
            "Times are medians of several runs after a warm-up; every baseline is measured in the same run, on the "
            "same machine and thread count as our figure. Ratio = baseline / ours for times (>1: ours is faster), "
            "ours / baseline for rates (samples/s). Each row's note gives its target where the issue sets one "
            "(met, or MISSED by how much).\n"
            f"{_load_line(before, after, peak)}{gpu_note}\n{table}\n\n"
            "Per module: " + ", ".join(f"`{n}` {d:.0f} s" for n, d in durations) + ".\n" + gpu_text)
    if failures:
        text += "\n## Benchmarks that failed\n\n" + "\n".join(f"- `{n}`: {e}" for n, e in failures) + "\n"
    if write:
        OUT.write_text(text)
    print(text)
    return text


if __name__ == "__main__":
    main()
