"""Progress lines of long loops: every 10 s and at the end of a long loop, silent in a quick one."""
from __future__ import annotations

import logging

import numpy as np
import trimesh

from lit3d.utils import progress as progress_module
from lit3d.utils.progress import progress, progress_line


class _Clock:
    """``time.monotonic`` that advances ``step`` seconds a call."""

    def __init__(self, step: float):
        self.now, self.step = 0.0, step

    def __call__(self) -> float:
        self.now += self.step
        return self.now


def test_lines_every_ten_seconds_and_at_the_end(monkeypatch):
    monkeypatch.setattr(progress_module.time, "monotonic", _Clock(4.0))  # each item "takes" 4 s
    lines = []
    assert list(progress(range(6), "tables", lines.append)) == list(range(6))
    # the loop starts at 4 s, item k ends at 4 (k + 1) s: a line after item 3 (12 s since the start)
    # and after item 6 (12 s since that line; the end)
    assert lines == ["tables: 3/6 (50%) after 12 s, about 12 s left", "tables: 6/6 done in 24 s"]


def test_quick_loop_is_silent_and_unknown_totals_count_up(monkeypatch):
    lines = []
    list(progress(range(100), "quick", lines.append))
    assert lines == []
    monkeypatch.setattr(progress_module.time, "monotonic", _Clock(11.0))
    list(progress(iter(range(2)), "stream", lines.append))
    assert lines == ["stream: 1 done after 11 s", "stream: 2 done after 22 s"]
    assert progress_line("x", 0, 0, 0.0) == "x: 0/0 done in 0 s"


def test_canonical_baselines_report_progress(monkeypatch, caplog):
    """The mesh baselines (canonical forms of every test mesh) log their progress through lit3d."""
    from lit3d.geometry.canonical_forms import canonical_forms_multi

    monkeypatch.setattr(progress_module, "EVERY_S", 0.0)
    sphere = trimesh.creation.icosphere(1)
    meshes = [(np.asarray(sphere.vertices), np.asarray(sphere.faces))] * 3
    with caplog.at_level(logging.INFO, logger="lit3d"):
        canonical_forms_multi(meshes, ["posed"])
    assert [r.getMessage() for r in caplog.records if r.name == "lit3d"][-1] == "canonical forms (posed): 3/3 done in 0 s"
