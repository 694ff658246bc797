"""Mean ± sd over training runs of pooled canonical results (``lit3d-summary --over-runs``), against the
standard library's statistics."""
import json
import statistics

import pytest

from lit3d.canonical.over_runs import load, markdown, over_runs
from lit3d.canonical.pooled import SCORES
from lit3d.cli.summary import main as summary_main


def main(argv):
    """``lit3d-summary --over-runs ARGV...``: its exit status."""
    with pytest.raises(SystemExit) as info:
        summary_main(["--over-runs", *argv])
    return info.value.code


def _write(d, nn, iou, n_items=68, seeds=(0, 1, 2, 3, 4)):
    d.mkdir(parents=True)
    summary = {"model": {s: [nn + i / 100, 0.01] for i, s in enumerate(SCORES)},
               "input": {s: [0.5, 0.02] for s in SCORES}}
    masks = {"model": {"iou": iou, "nearest_subject": iou / 2, "nn_by_mask": 0.3, "ft_by_mask": 0.2}}
    (d / "pooled.json").write_text(json.dumps({"summary": summary, "mask_match": masks, "n_items": n_items,
                                               "seeds": list(seeds)}))
    return d


def test_mean_and_sd_over_runs_match_statistics(tmp_path, capsys):
    nns, ious = [0.44, 0.37, 0.31, 0.28], [0.59, 0.63, 0.59, 0.54]
    dirs = [_write(tmp_path / f"run{i}", nn, iou) for i, (nn, iou) in enumerate(zip(nns, ious))]
    table = over_runs(load(dirs))
    nn = table["scores"]["model"]["nn"]
    assert nn["mean"] == pytest.approx(statistics.mean(nns)) and nn["sd"] == pytest.approx(statistics.stdev(nns))
    assert nn["runs"] == pytest.approx(nns)
    ft = table["scores"]["model"]["ft"]
    assert ft["mean"] == pytest.approx(statistics.mean(nns) + 0.01)
    assert table["scores"]["input"]["nn"]["sd"] == 0.0
    iou = table["masks"]["model"]["iou"]
    assert iou["sd"] == pytest.approx(statistics.stdev(ious))
    assert "input" not in table["masks"]  # no mask check for that row in these files
    text = markdown(table, ["a", "b", "c", "d"])
    assert "| model | 0.35 ± 0.07 (0.44 0.37 0.31 0.28) |" in text
    out = tmp_path / "over.md"
    assert main([str(d) for d in dirs] + ["--out", str(out)]) == 0
    assert out.read_text() == capsys.readouterr().out and "| model | 0.35 ± 0.07" in out.read_text()
    from studies.canonical.over_runs import main as study_main  # the LOG's command: the same code

    assert study_main([str(d) for d in dirs]) == 0 and capsys.readouterr().out == out.read_text()


def test_runs_of_different_protocols_or_bad_files_are_one_line(tmp_path, capsys):
    a = _write(tmp_path / "a", 0.4, 0.6)
    b = _write(tmp_path / "b", 0.4, 0.6, n_items=26)
    with pytest.raises(ValueError, match=r"b: 26 items.*not the same protocol"):
        load([a, b])
    (tmp_path / "c").mkdir()
    (tmp_path / "c" / "pooled.json").write_text('{"summary": {}, "n_items": 68')  # cut short
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "pooled.json").write_text('{"summary": {}}')
    out = tmp_path / "over.md"
    for other, message in [(b, f"{b}: 26 items, codebook seeds [0, 1, 2, 3, 4]; {a} has 68 items"),
                           (tmp_path / "nowhere", f"{tmp_path / 'nowhere' / 'pooled.json'}: missing"),
                           (tmp_path / "c", f"{tmp_path / 'c' / 'pooled.json'}: not a pooled result (not JSON"),
                           (tmp_path / "d", f"{tmp_path / 'd' / 'pooled.json'}: not a pooled result (no n_items, seeds")]:
        assert main([str(a), str(other), "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith(f"lit3d-summary: error: {message}") and "\n" not in err, err
    assert not out.exists()  # nothing written


def test_confusion_counts_who_is_taken_for_whom(tmp_path):
    """Two subjects whose canonical masks are the left and right half; a/2's prediction is the right
    half (taken for b), the others their own: counts [[1, 1], [0, 1]] per run, summed over two runs."""
    import numpy as np

    from lit3d.canonical import heldout
    from lit3d.canonical.over_runs import confusion, confusion_markdown

    left, right = np.zeros((4, 4), np.float16), np.zeros((4, 4), np.float16)
    left[:, :2], right[:, 2:] = 1, 1
    ids = ["a/1/0", "a/2/0", "b/1/0"]
    canon = {"a": left, "b": right}
    pred = {"a/1/0": left, "a/2/0": right, "b/1/0": right}

    def fold(sweep, f, items):
        arr = {k: np.stack([canon[i[0]] for i in items]) for k in heldout.IMAGES}
        arr["pred_mask"] = np.stack([pred[i] for i in items])
        arr.update(subject=np.array([i.split("/")[0] for i in items]), pose=np.array([int(i[2]) for i in items]),
                   view=np.zeros(len(items), np.int64), item=np.array(items), expected=np.array(ids),
                   source=np.array("model"), fold=np.array(f), n_folds=np.array(2), data=np.array("{}"),
                   settings=np.array("{}"))
        (sweep / str(f)).mkdir(parents=True)
        heldout.save_heldout(sweep / str(f) / heldout.HELDOUT_FILE, arr)

    sweeps = []
    for run in ("r1", "r2"):
        fold(tmp_path / run, 0, ids[:2])
        fold(tmp_path / run, 1, ids[2:])
        sweeps.append(tmp_path / run)
    names, counts = confusion(sweeps)
    assert names == ["a", "b"] and counts.tolist() == [[2, 2], [0, 2]]
    text = confusion_markdown(names, counts)
    assert "| a | 2 | 2 | 0.50 |" in text and "| b | 0 | 2 | 1.00 |" in text and "Overall: 0.67 of 6" in text
    with pytest.raises(ValueError, match="no row 'unet'"):
        confusion(sweeps, row="unet")
