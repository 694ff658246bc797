"""curves.png from Lightning CSV logs: which columns, resumed runs, ticks, panel sizes."""
from __future__ import annotations

import csv

import numpy as np
from PIL import Image

from lit3d.utils.curves import (PANEL_H, PANEL_W, curves_figure, nice_ticks, panels, read_csv_logs, tick_labels,
                                write_curves)


def _write(path, rows):
    keys = sorted({k for r in rows for k in r})
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, keys)
        w.writeheader()
        w.writerows(rows)
    return path


def test_resumed_log_replaces_the_steps_it_repeats(tmp_path):
    first = _write(tmp_path / "v0.csv", [{"step": s, "train/loss": 10 - s} for s in range(0, 10)])
    # resumed from a checkpoint at step 6: steps 6.. are logged again
    second = _write(tmp_path / "v1.csv", [{"step": s, "train/loss": 100 + s} for s in range(6, 12)])
    steps, values = read_csv_logs([first, second])["train/loss"]
    assert steps.tolist() == list(range(12))
    assert values.tolist() == [10 - s for s in range(6)] + [100 + s for s in range(6, 12)]


def test_empty_cells_and_nan_are_skipped(tmp_path):
    path = _write(tmp_path / "m.csv", [{"step": 0, "epoch": 0, "train/loss": 1.0, "val/iou": ""},
                                      {"step": 5, "epoch": 0, "train/loss": "", "val/iou": 0.5},
                                      {"step": 9, "epoch": 1, "train/loss": "nan", "val/iou": 0.6}])
    series = read_csv_logs([path])
    assert set(series) == {"train/loss", "val/iou"}  # step and epoch are the axis, not series
    assert series["train/loss"][0].tolist() == [0] and series["val/iou"][1].tolist() == [0.5, 0.6]


def test_panels_train_then_val_step_and_epoch_together():
    s = (np.arange(3.0), np.ones(3))
    series = {"val/iou": s, "train/bce_step": s, "train/bce_epoch": s, "health/a/grad_norm": s,
              "test/same/iou": s, "train/loss_g": s}
    drawn = panels(series)
    assert [name for name, _ in drawn] == ["train/bce", "train/loss_g", "val/iou"]
    assert [label for label, *_ in drawn[0][1]] == ["per step", "epoch mean"]


def test_ticks_are_round_and_labels_distinct():
    assert nice_ticks(0, 2000, integer=True) == [0, 500, 1000, 1500, 2000]
    assert nice_ticks(7, 7, integer=True) == [6, 7, 8]  # one step: whole-number ticks around it
    ticks = nice_ticks(0.2735, 0.2755)
    assert ticks[0] <= 0.2735 and ticks[-1] >= 0.2755 and len(ticks) <= 7
    labels = tick_labels(ticks)
    assert len(set(labels)) == len(labels)
    assert tick_labels([0, 1000, 2000]) == ["0", "1,000", "2,000"]


def test_figure_has_a_readable_panel_per_metric(tmp_path):
    rows = [{"step": s, "train/loss_step": 5 * np.exp(-s / 300) + 0.01} for s in range(0, 2000, 10)]
    rows += [{"step": s, "val/iou": 0.3 + s / 10000, "val/ce": 0.5 - s / 10000} for s in range(199, 2000, 200)]
    out = write_curves([_write(tmp_path / "m.csv", rows)], tmp_path / "curves.png", "test run")
    img = Image.open(out)
    assert img.size == (3 * PANEL_W, 48 + PANEL_H) and min(PANEL_W, PANEL_H) >= 256
    pixels = np.asarray(img.convert("RGB")).reshape(-1, 3)
    assert ((pixels[:, 2] > 150) & (pixels[:, 0] < 80)).sum() > 500  # the curves are drawn (blue)


def test_nothing_to_draw_writes_nothing(tmp_path):
    path = _write(tmp_path / "m.csv", [{"step": 0, "health/x": 1.0, "test/iou": 0.5}])
    assert write_curves([path], tmp_path / "curves.png", "t") is None and not (tmp_path / "curves.png").exists()
    assert curves_figure({}, "t") is None
