"""The demo-folder comparer (studies.layout.compare_demo) on tiny fake demo folders."""
import json

import pytest

from studies.layout.compare_demo import BadInput, json_values, main, text_values

SUMMARY = """completion (shape completion from one depth view; test IoU: same 0.412 (input 0.205); cross 0.398 (input 0.201))
  evaluation       {d}/eval/results.md  {d}/eval/metrics.json
  figures          {d}/eval/same_0.png {d}/eval/same_1.png
  (completion: {secs} s)
"""


def _demo(root, name, *, iou="0.4123456789", manifest_hash="ab" * 32, secs=412, wall="12.5", summary_iou="0.412"):
    d = root / name
    (d / "eval").mkdir(parents=True)
    (d / "root/data/completion_demo_synth").mkdir(parents=True)
    (d / "eval/metrics.json").write_text(
        f'{{"test/same/iou": {iou}, "test/same/n": 60, "test_time_s": {wall}, "timing": {{"seconds": {wall}}}}}')
    (d / "root/data/completion_demo_synth/manifest.json").write_text(json.dumps(
        {"manifest_hash": manifest_hash, "config_hash": "cd" * 32, "items": [{"file": "a.npz"}]}))
    (d / "summary_completion.txt").write_text(SUMMARY.format(d=d, secs=secs).replace("0.412", summary_iou))
    return d


def test_equal_folders_pass_with_other_paths_and_times(tmp_path, capsys):
    a = _demo(tmp_path, "a")
    b = _demo(tmp_path, "b", secs=977, wall="99.0")  # only the folder name and the wall-clock fields differ
    assert main([str(a), str(b)]) == 0
    out = capsys.readouterr().out
    assert "SAME" in out and "0 differ" in out


def test_a_changed_last_digit_fails(tmp_path, capsys):
    a = _demo(tmp_path, "a")
    b = _demo(tmp_path, "b", iou="0.4123456788")
    assert main([str(a), str(b)]) == 1
    out = capsys.readouterr().out
    assert "| eval/metrics.json | test/same/iou | 0.4123456789 | 0.4123456788 | **no** |" in out


def test_a_changed_digit_in_a_summary_line_fails(tmp_path, capsys):
    a = _demo(tmp_path, "a")
    b = _demo(tmp_path, "b", summary_iou="0.413")
    assert main([str(a), str(b)]) == 1
    assert "| summary_completion.txt | L1#1 same | 0.412 | 0.413 | **no** |" in capsys.readouterr().out


def test_a_changed_manifest_hash_fails(tmp_path, capsys):
    a = _demo(tmp_path, "a")
    b = _demo(tmp_path, "b", manifest_hash="ab" * 31 + "ac")
    assert main([str(a), str(b)]) == 1
    assert "root/data/completion_demo_synth/manifest.json | manifest_hash" in capsys.readouterr().out


def test_a_file_in_one_folder_only_fails(tmp_path, capsys):
    a = _demo(tmp_path, "a")
    b = _demo(tmp_path, "b")
    (b / "eval/metrics.json").rename(b / "eval/other.json")
    assert main([str(a), str(b)]) == 1
    assert "| eval/metrics.json | (file) | present | - | **no** |" in capsys.readouterr().out


def test_printed_numbers_skip_paths_and_times(tmp_path):
    # the model and input IoU of 'same' and 'cross' on line 1; none from the path lines (digits in folder
    # names) nor from the closing time line
    p = tmp_path / "summary.txt"
    p.write_text(SUMMARY.format(d="/tmp/demo_9/x2", secs=31))
    assert text_values(p) == {"L1#1 same": "0.412", "L1#2 input": "0.205", "L1#3 cross": "0.398", "L1#4 input": "0.201"}


def test_bad_folder_and_bad_json_exit_2(tmp_path, capsys):
    a = _demo(tmp_path, "a")
    assert main([str(a), str(tmp_path / "missing")]) == 2
    assert "missing: no such folder" in capsys.readouterr().err
    b = _demo(tmp_path, "b")
    (b / "eval/metrics.json").write_text("{not json")
    assert main([str(a), str(b)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "eval/metrics.json: unreadable JSON" in err


def test_console_lines_after_a_data_summary_are_skipped_elsewhere_refused(tmp_path, capsys):
    a = _demo(tmp_path, "a")
    b = _demo(tmp_path, "b")
    (a / "data_summary.json").write_text('{"counts": {"train": 720}}')
    (b / "data_summary.json").write_text('{"counts": {"train": 720}}\n[12:00:01][lit3d][INFO] - wrote samples.png\n')
    assert main([str(a), str(b)]) == 0
    assert "data_summary.json: text after the JSON summary skipped" in capsys.readouterr().err
    (b / "data_summary.json").write_text('{"counts": {"train": 721}}\nwrote samples.png\n')
    assert main([str(a), str(b)]) == 1
    (b / "eval/metrics.json").write_text('{"test/same/iou": 0.4123456789}\nextra')
    assert main([str(a), str(b)]) == 2


def test_log_lines_before_a_data_summary_are_skipped(tmp_path, capsys):
    """Older checkouts printed lit3d-data's warnings on stdout, before the JSON summary."""
    path = tmp_path / "data_summary.json"
    path.write_text("[2026-11-29 05:06:01,350][lit3d.data][WARNING] - bench keeps procedural\n"
                    '{"bytes_on_disk": 12, "config_hash": "ab"}\n')
    assert json_values(path) == {"bytes_on_disk": "12", "config_hash": "ab"}
    assert "1 log lines before the JSON summary skipped" in capsys.readouterr().err
    (tmp_path / "x.json").write_text("[2026-11-29 05:06:01,350] not skipped here\n{}")
    with pytest.raises(BadInput, match="unreadable JSON"):
        json_values(tmp_path / "x.json")
