"""``make bench``: run every ``benchmarks/bench_*.py`` and rewrite BENCHMARKS.md.

Each module has ``run() -> list[dict]`` (rows from ``benchmarks.common.row``). A module
that fails is reported in the file with its error instead of silently vanishing.
"""
from __future__ import annotations

import datetime
import importlib
import pkgutil
import sys
import traceback
from pathlib import Path

import benchmarks
from benchmarks.common import machine
from lit3d.reports.tables import markdown_table

OUT = Path(__file__).resolve().parents[1] / "BENCHMARKS.md"


def _num(v, unit: str) -> str:
    if v is None:
        return "–"
    return f"{v:.4g} {unit}".strip()


def main(selected: list[str] | None = None) -> None:
    names = sorted(m.name for m in pkgutil.iter_modules(benchmarks.__path__) if m.name.startswith("bench_"))
    if selected:
        names = [n for n in names if any(s in n for s in selected)]
    rows, failures = [], []
    for name in names:
        print(f"[bench] {name} ...", flush=True)
        try:
            rows += importlib.import_module(f"benchmarks.{name}").run()
        except Exception as exc:  # keep the other rows
            failures.append((name, f"{type(exc).__name__}: {exc}"))
            traceback.print_exc()
    table = markdown_table(
        ["benchmark", "machine", "ours", "baseline (same run)", "ratio baseline/ours", "note", "command"],
        [[r["name"], r["machine"], _num(r["ours"], r["unit"]),
          (f"{r['baseline_name']}: " if r.get("baseline_name") else "") + _num(r["baseline"], r["unit"]),
          "–" if r["ratio"] is None else f"{r['ratio']:.2f}x", r["note"], f"`{r['command']}`"] for r in rows],
    )
    gpu_note = ("" if "GPU" in machine() else
                "\nNo NVIDIA GPU was available for this run: the paper-scale GPU rows were not measured.\n")
    text = (f"# Benchmarks\n\nWritten by `make bench` on {datetime.date.today()} — {machine()}.\n"
            "Times are medians of several runs after a warm-up; baselines are measured in the same run.\n"
            f"{gpu_note}\n{table}\n")
    if failures:
        text += "\n## Benchmarks that failed\n\n" + "\n".join(f"- `{n}`: {e}" for n, e in failures) + "\n"
    OUT.write_text(text)
    print(text)


if __name__ == "__main__":
    main(sys.argv[1:])
