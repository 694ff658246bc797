"""Progress lines of long loops: every 10 s and at the end of a long loop, silent in a quick one; the heartbeat of
one long step (its lines, and silence once the step has ended)."""
from __future__ import annotations

import logging
import time

import numpy as np
import trimesh

from lit3d.utils import progress as progress_module
from lit3d.utils.progress import duration, heartbeat_line, progress, progress_line, ticking


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


def test_heartbeat_lines_say_the_time_and_what_is_left():
    assert [duration(s) for s in (0.4, 40, 60, 110, 150)] == ["0 s", "40 s", "1 min", "1 min 50 s", "2 min 30 s"]
    assert heartbeat_line("building", 40, 150) == "building: 40 s, about 1 min 50 s left"
    assert heartbeat_line("building", 190, 150) == \
        "building: 3 min 10 s, longer than the usual 2 min 30 s (a busy machine is slower)"


def test_ticking_beats_while_the_block_runs_and_stops_with_it():
    lines = []
    with ticking("step", expected_s=100, emit=lines.append, every_s=0.25):
        time.sleep(1.2)
    n = len(lines)
    assert 2 <= n <= 5 and all(ln.startswith("step: ") and ln.endswith(" s left") for ln in lines), lines
    time.sleep(0.6)
    assert len(lines) == n, "a heartbeat after the block ended"
    with ticking("quick", expected_s=100, emit=lines.append, every_s=0.25):
        pass
    assert len(lines) == n, "a quick step said something"
