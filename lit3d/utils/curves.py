"""Learning curves of a run as one labelled PNG (Pillow): one panel per logged loss or validation
metric against the training step, read from Lightning's CSV logs.

    series = read_csv_logs([run / "csv/version_0/metrics.csv"])   # {name: (steps, values)}
    curves_figure(series, "completion, run X").save("curves.png")

Plotted: the ``train/`` and ``val/`` columns (``health/`` and ``test/`` are left out), a metric's
``_step`` and ``_epoch`` columns in one panel; each panel shows its curves with the step axis,
ticks, the last, lowest and highest value; positive values spanning more than two decades are
drawn on a log scale (said in the panel's title).
"""
from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from lit3d.utils.figures import font
from lit3d.utils.io import atomic_write_bytes

PREFIXES = ("train/", "val/")
MAX_PANELS = 24
PANEL_W, PANEL_H, COLUMNS, TITLE_H = 420, 300, 3, 48
LEFT, RIGHT, TOP, BOTTOM = 70, 16, 40, 46  # plot-area margins inside a panel
GRID, AXIS, TEXT = (225, 225, 225), (90, 90, 90), (0, 0, 0)
COLOURS = ((31, 119, 180), (230, 120, 20), (40, 160, 60))

Series = dict[str, tuple[np.ndarray, np.ndarray]]


def read_csv_logs(paths: Sequence[str | Path]) -> Series:
    """``{column: (steps (n,) float64, values (n,) float64)}`` of Lightning ``metrics.csv`` files, in
    the order given (oldest first): a later file (a resumed run) replaces the earlier ones' rows from
    its first step on. Empty cells are skipped; files without a ``step`` column add nothing."""
    points: dict[str, dict[float, float]] = {}
    for path in paths:
        with open(path, newline="") as f:
            rows = [r for r in csv.DictReader(f) if _number(r.get("step")) is not None]
        if not rows:
            continue
        first = min(_number(r["step"]) for r in rows)
        for d in points.values():
            for s in [s for s in d if s >= first]:
                del d[s]
        for r in rows:
            step = _number(r["step"])
            for key, cell in r.items():
                value = _number(cell)
                if key not in ("step", "epoch") and value is not None and math.isfinite(value):
                    points.setdefault(key, {})[step] = value
    return {k: (np.array(sorted(d)), np.array([d[s] for s in sorted(d)])) for k, d in points.items() if d}


def _number(cell) -> float | None:
    try:
        return float(cell)
    except (TypeError, ValueError):
        return None


def panels(series: Series) -> list[tuple[str, list[tuple[str, np.ndarray, np.ndarray]]]]:
    """What is drawn: ``[(metric, [(label, steps, values), ...])]``, ``train/`` metrics then ``val/``
    ones, each group sorted by name, at most :data:`MAX_PANELS`. Lightning's ``<m>_step`` and
    ``<m>_epoch`` columns (a metric logged per step and as an epoch mean) share the panel ``<m>``."""
    groups: dict[str, list[tuple[str, np.ndarray, np.ndarray]]] = {}
    for key in sorted(series):
        if not key.startswith(PREFIXES):
            continue
        for suffix, label in (("_step", "per step"), ("_epoch", "epoch mean")):
            if key.endswith(suffix):
                groups.setdefault(key.removesuffix(suffix), []).append((label, *series[key]))
                break
        else:
            groups.setdefault(key, []).insert(0, ("", *series[key]))
    order = [k for p in PREFIXES for k in sorted(groups) if k.startswith(p)]
    return [(k, sorted(groups[k], key=lambda c: c[0] != "per step")) for k in order[:MAX_PANELS]]


def curves_figure(series: Series, title: str) -> Image.Image | None:
    """One panel per entry of :func:`panels` (``PANEL_W x PANEL_H`` px, :data:`COLUMNS` a row);
    None when there is nothing to draw."""
    drawn = panels(series)
    if not drawn:
        return None
    cols = min(COLUMNS, len(drawn))
    rows = math.ceil(len(drawn) / cols)
    img = Image.new("RGB", (cols * PANEL_W, TITLE_H + rows * PANEL_H), "white")
    draw = ImageDraw.Draw(img)
    draw.text((10, 12), title, fill=TEXT, font=font(20))
    for i, (name, curves) in enumerate(drawn):
        draw_panel(draw, ((i % cols) * PANEL_W, TITLE_H + (i // cols) * PANEL_H), name, curves)
    return img


def draw_panel(draw: ImageDraw.ImageDraw, origin: tuple[int, int], name: str,
               curves: list[tuple[str, np.ndarray, np.ndarray]]) -> None:
    """One metric's curves ``[(label, steps, values)]`` against step in the ``PANEL_W x PANEL_H`` box
    at ``origin``; the last curve's last value, and the lowest and highest of all, top right."""
    x0, y0 = origin
    steps = np.concatenate([c[1] for c in curves])
    values = np.concatenate([c[2] for c in curves])
    log_y = bool((values > 0).all() and values.max() / values.min() > 100)
    px0, px1, py0, py1 = x0 + LEFT, x0 + PANEL_W - RIGHT, y0 + TOP, y0 + PANEL_H - BOTTOM
    draw.text((x0 + 8, y0 + 8), name + ("  (log scale)" if log_y else ""), fill=TEXT, font=font(16))
    draw.text((px1, y0 + 30), f"last {_fmt(curves[-1][2][-1])}  min {_fmt(values.min())}  max {_fmt(values.max())}",
              fill=AXIS, font=font(12), anchor="rb")
    ys = np.log10(values) if log_y else values
    xt, yt = nice_ticks(float(steps.min()), float(steps.max()), integer=True), nice_ticks(float(ys.min()), float(ys.max()))
    xlo, xhi, ylo, yhi = xt[0], xt[-1], yt[0], yt[-1]

    def to_px(s: np.ndarray, v: np.ndarray) -> list[tuple[float, float]]:
        v = np.log10(v) if log_y else v
        return list(zip((px0 + (s - xlo) / (xhi - xlo) * (px1 - px0)).tolist(),
                        (py1 - (v - ylo) / (yhi - ylo) * (py1 - py0)).tolist()))

    small = font(12)
    for t, text in zip(xt, tick_labels(xt)):
        x = px0 + (t - xlo) / (xhi - xlo) * (px1 - px0)
        draw.line([(x, py0), (x, py1)], fill=GRID)
        draw.text((x, py1 + 6), text, fill=AXIS, font=small, anchor="mt")
    for t, text in zip(yt, tick_labels([10 ** t for t in yt] if log_y else yt)):
        y = py1 - (t - ylo) / (yhi - ylo) * (py1 - py0)
        draw.line([(px0, y), (px1, y)], fill=GRID)
        draw.text((px0 - 6, y), text, fill=AXIS, font=small, anchor="rm")
    draw.rectangle([px0, py0, px1, py1], outline=AXIS)
    draw.text(((px0 + px1) / 2, y0 + PANEL_H - 8), "step", fill=TEXT, font=font(13), anchor="mb")
    for k, (label, s, v) in enumerate(curves):
        colour = COLOURS[k % len(COLOURS)]
        pts = to_px(s, v)
        if len(pts) > 1:
            draw.line(pts, fill=colour, width=2 if k == 0 else 1)
        if len(pts) <= 40 or k > 0:
            for x, y in pts:
                draw.ellipse([x - 3, y - 3, x + 3, y + 3], fill=colour)
        if label and len(curves) > 1:  # legend, top left: a dot and the label in the curve's colour
            ly = py0 + 12 + 16 * k
            draw.ellipse([px0 + 8, ly - 3, px0 + 14, ly + 3], fill=colour)
            draw.text((px0 + 20, ly), label, fill=colour, font=small, anchor="lm")


def tick_labels(ticks: Sequence[float]) -> list[str]:
    """Tick texts with as few significant digits as keep them distinct (integers with thousands commas)."""
    if all(abs(t - round(t)) < 1e-9 for t in ticks) and max(abs(t) for t in ticks) < 1e7:
        return [f"{int(round(t)):,}" for t in ticks]
    for digits in range(2, 9):
        texts = [f"{t:.{digits}g}" for t in ticks]
        if len(set(texts)) == len(texts):
            return texts
    return texts


def nice_ticks(lo: float, hi: float, n: int = 5, integer: bool = False) -> list[float]:
    """About ``n`` round tick values (steps of 1, 2, 2.5 or 5 x 10^k; whole steps of at least 1 when
    ``integer``) covering ``[lo, hi]``."""
    if not hi > lo:
        pad = 1.0 if integer else abs(lo) * 0.05 or 1.0
        lo, hi = lo - pad, hi + pad
    raw = (hi - lo) / max(n - 1, 1)
    mag = 10 ** math.floor(math.log10(raw))
    step = next(m * mag for m in (1, 2, 2.5, 5, 10) if m * mag >= raw * (1 - 1e-9))
    if integer:
        step = max(1, round(step)) if step < 10 else step
    first, last = math.floor(lo / step + 1e-9), math.ceil(hi / step - 1e-9)
    return [k * step for k in range(first, last + 1)]


def _fmt(v: float) -> str:
    """3 significant digits; 1,000 .. 9,999,999 in full with thousands commas (not 1e+03)."""
    return f"{v:,.0f}" if 1000 <= abs(v) < 1e7 else f"{v:.3g}"


def write_curves(csv_paths: Sequence[str | Path], out_png: str | Path, title: str) -> Path | None:
    """Draw :func:`curves_figure` of the CSV logs into ``out_png`` (written atomically); None (and
    no file) when the logs hold no ``train/`` or ``val/`` value."""
    img = curves_figure(read_csv_logs(csv_paths), title)
    if img is None:
        return None
    buf = io.BytesIO()
    img.save(buf, format="PNG")
    atomic_write_bytes(Path(out_png), buf.getvalue())
    return Path(out_png)
