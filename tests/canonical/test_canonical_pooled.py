"""Pooled cross-validated retrieval: held-out items saved per fold, merged with every
item exactly once, every row scored on the same items over several codebook seeds."""
import json
from types import SimpleNamespace

import numpy as np
import pytest
from lightning.fabric.utilities.data import AttributeDict

from lit3d.canonical import evaluator, heldout
from lit3d.utils.evaluation import Evaluation
from tests.helpers.canonical import RETRIEVAL, fold_outputs, pooled_datamodule







def test_held_out_ids_cover_every_posed_item_once_over_the_folds(tmp_path):
    dm = pooled_datamodule(tmp_path, view_mode="broadside", flip_lr=True)
    ids = dm.held_out_ids()
    assert len(ids) == 4 * 3 and len(set(ids)) == len(ids)  # every non-canonical pose of every subject
    tested = []
    for f in range(3):
        rows = pooled_datamodule(tmp_path, f, view_mode="broadside").splits["test"]
        tested += [f"{r['subject']}/{r['pose']}/{r['view']}" for r in rows]
    assert sorted(tested) == sorted(ids)
    assert dm.datasets["train"].flip_lr and not dm.datasets["test"].flip_lr
    assert dm.cache_config()["view_mode"] == "broadside"
    assert "view_mode" not in pooled_datamodule(tmp_path / "fixed").cache_config()  # old caches keep their hash


def test_pool_checks_coverage():
    def fold(items, f):
        n = len(items)
        z = np.zeros((n, 4, 4), np.float16)
        return {**{k: z for k in heldout.IMAGES}, "subject": np.array([i.split("/")[0] for i in items]),
                "pose": np.ones(n, np.int64), "view": np.zeros(n, np.int64), "item": np.array(items),
                "expected": np.array(["a/1/0", "a/2/0", "b/1/0"]), "source": np.array("model"),
                "fold": np.array(f), "n_folds": np.array(2), "data": np.array("{}"), "settings": np.array("{}")}

    def pool_of(tmp, *folds):
        dirs = []
        for i, items in enumerate(folds):
            d = tmp / f"f{i}"
            d.mkdir()
            heldout.save_heldout(d / heldout.HELDOUT_FILE, fold(items, i))
            dirs.append(d)
        return dirs

    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as t:
        merged = heldout.pool(pool_of(Path(t), ["b/1/0", "a/1/0"], ["a/2/0"]))
        assert merged["item"].tolist() == ["a/1/0", "a/2/0", "b/1/0"] and merged["folds"].tolist() == [0, 1]
    with tempfile.TemporaryDirectory() as t:
        with pytest.raises(ValueError, match="more than once"):
            heldout.pool(pool_of(Path(t), ["a/1/0", "b/1/0"], ["a/1/0", "a/2/0"]))
    with tempfile.TemporaryDirectory() as t:
        dirs = pool_of(Path(t), ["a/1/0"], ["a/2/0"])
        with pytest.raises(ValueError, match="never held out"):
            heldout.pool(dirs)
        assert len(heldout.pool(dirs, strict=False)["item"]) == 2


def summary(argv: list[str]) -> int:
    """``lit3d-summary ARGV...``: its exit status."""
    from lit3d.cli.summary import main

    with pytest.raises(SystemExit) as info:
        main(argv)
    return info.value.code


def test_folds_write_heldout_and_the_pooled_evaluator_scores_every_row(tmp_path, capsys):
    """The folds' heldout.npz pooled by ``lit3d-summary --pooled``: every row scored per seed; folds that do
    not cover the data are one line, exit 2, nothing written."""
    hp = AttributeDict(arch="canonical", mask_threshold=0.5)  # the task's; the rest are evaluation settings
    settings = dict(retrieval=RETRIEVAL, chance_trials=5, mesh_baselines=["gps"], baseline_landmarks=30,
                    baseline_max_vertices=None, baseline_smacof_eps=1e-4)
    runs = []
    for f in range(3):
        dm = pooled_datamodule(tmp_path, f)
        held = evaluator.heldout_items(SimpleNamespace(hparams=hp, _trainer=None), fold_outputs(dm), dm, settings)
        run = tmp_path / f"run{f}"
        assert evaluator.write_artefacts(Evaluation({}, {"heldout": held}), run) == [run / heldout.HELDOUT_FILE]
        evaluator.write_results({"test/depth_mse": 0.1}, run)
        assert (run / heldout.HELDOUT_FILE).is_file() and (run / "results.md").is_file()
        runs.append(run)
    assert evaluator.write_artefacts(Evaluation(), tmp_path / "none") == []  # nothing held out: no file
    capsys.readouterr()  # the folds' data preparation
    assert summary(["--pooled", *map(str, runs[:2]), "--seeds", "0", "--out", str(tmp_path / "partial")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("lit3d-summary: error: pooled held-out items do not cover the data once:") and \
        "never held out" in err and "\n" not in err, err
    assert not (tmp_path / "partial").exists()  # nothing written
    assert summary(["--pooled", *map(str, runs), "--seeds", "0", "1", "--out", str(tmp_path / "pooled")]) == 0
    text = (tmp_path / "pooled" / "pooled_results.md").read_text()
    assert capsys.readouterr().out.strip() == text.strip()
    res = json.loads((tmp_path / "pooled" / "pooled.json").read_text())
    assert res["n_items"] == 12 and res["seeds"] == [0, 1]
    for row in ("model", "input", "target", "gps", "shapedna", "chance"):
        assert len(res["per_seed"][row]["nn"]) == 2, row
        assert all(0 <= v <= 1 for v in res["per_seed"][row]["nn"])
    # the 'prediction' is the posed input here: the same images, so the same scores for every seed
    assert res["per_seed"]["model"] == res["per_seed"]["input"]
    assert res["summary"]["shapedna"]["nn"][1] == 0  # no codebook: no spread over seeds
    assert "table 5.1" in text and "±" in text and "ShapeDNA of the posed full mesh" in text


def test_mask_match_against_sklearn_jaccard():
    """Prediction = the truth: IoU 1, every item nearest its own subject and retrieved perfectly by
    mask IoU; prediction = the next subject's canonical mask: nearest 0; the posed-input IoU equals
    sklearn's Jaccard per item, its retrieval by mask IoU that of SciPy's Jaccard distances."""
    from scipy.spatial.distance import cdist
    from sklearn.metrics import jaccard_score

    from lit3d.canonical.pooled import mask_match
    from lit3d.metrics.retrieval import retrieval_scores

    rng = np.random.default_rng(0)
    canon = rng.random((3, 1, 16, 16)) > 0.5
    subject = np.array(["a", "a", "b", "c", "c", "b"])
    idx = np.array([0, 0, 1, 2, 2, 1])
    truth = canon[idx].astype(np.float32)
    posed = (rng.random((6, 1, 16, 16)) > 0.4).astype(np.float32)
    items = {"subject": subject, "canon_mask": truth, "mask": posed, "pred_mask": truth.copy(), "source": "model"}
    out = mask_match(items, 0.5)
    iou_other = out["model"].pop("iou_other")
    assert out["model"] == {"iou": 1.0, "nearest_subject": 1.0, "nn_by_mask": 1.0, "ft_by_mask": 1.0,
                            "iou_same": 1.0}
    flat = posed.reshape(6, -1) > 0.5
    ref_dist = cdist(flat, flat, metric="jaccard")  # scipy's 1 - IoU
    canon_dist = cdist(canon.reshape(3, -1), canon.reshape(3, -1), metric="jaccard")
    assert iou_other == pytest.approx(1 - canon_dist[idx][:, idx][subject[:, None] != subject[None]].mean())
    same_pairs = [(i, j) for i in range(6) for j in range(6) if i != j and subject[i] == subject[j]]
    assert out["input"]["iou_same"] == pytest.approx(np.mean([1 - ref_dist[i, j] for i, j in same_pairs]))
    ref_scores = retrieval_scores(ref_dist, subject)
    assert out["input"]["nn_by_mask"] == pytest.approx(ref_scores["nn"])
    assert out["input"]["ft_by_mask"] == pytest.approx(ref_scores["ft"])
    ref = np.mean([jaccard_score(truth[i].ravel() > 0.5, posed[i].ravel() > 0.5) for i in range(6)])
    assert out["input"]["iou"] == pytest.approx(ref, abs=1e-6)
    items["pred_mask"] = canon[(idx + 1) % 3].astype(np.float32)
    assert mask_match(items, 0.5)["model"]["nearest_subject"] == 0.0


def test_pooled_table_keeps_every_depth_row(tmp_path):
    """A depth row of any name (``--depth-row body_fit_refined=DIR``) gets its own line in pooled_results.md,
    before chance; the known rows keep their labels."""
    from lit3d.canonical.report import write_pooled_results

    scores = {k: (0.5, 0.01) for k in ("nn", "ft", "st", "e", "dcg")}
    result = {"summary": {"input": scores, "body_fit": scores, "body_fit_refined": dict(scores, nn=(0.46, 0.04)),
                          "chance": scores},
              "data": {"source": "tosca"}, "n_items": 36, "n_subjects": 3, "seeds": [0, 1]}
    lines = write_pooled_results(result, tmp_path).read_text().splitlines()
    rows = [line.split(" |")[0].lstrip("| ") for line in lines if "ours)" in line and line.startswith("|")]
    assert rows == ["posed input depth, no canonicalisation (ours)", "Anny body fit, its canonical depth (lit3d.body_fit, ours)",
                    "body_fit_refined: depth images from --depth-row (ours)", "chance: random distances (ours)"]
    assert "| 0.46 ± 0.04 |" in next(line for line in lines if "body_fit_refined" in line)


def test_pooled_command_line_refuses_bad_input_in_one_line(tmp_path, capsys):
    """``lit3d-summary --pooled`` (and the LOG's ``python -m studies.canonical.pooled``, the same code): a run
    dir without heldout.npz, nothing to pool, a bad --depth-row, --out a file: one line, exit 2, nothing written."""
    from studies.canonical.pooled import main as study_main

    (tmp_path / "run").mkdir()
    (tmp_path / "file").write_text("not a folder")
    out = str(tmp_path / "out")
    cases = [(["--pooled", str(tmp_path / "run"), "--out", out], f"{tmp_path / 'run' / heldout.HELDOUT_FILE}: "),
             (["--pooled", "--out", out], "--pooled: give run dirs, or Hydra overrides after --"),
             (["--pooled", str(tmp_path / "run"), "--depth-row", "body_fit", "--out", out],
              "--depth-row body_fit: expected ROW=DIR"),
             (["--pooled", str(tmp_path / "run"), "--out", str(tmp_path / "file")], f"{tmp_path / 'file'}: --out is a file")]
    for argv, message in cases:
        assert summary(argv) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith(f"lit3d-summary: error: {message}") and "\n" not in err, err
    assert study_main([str(tmp_path / "run"), "--out", out]) == 2
    assert capsys.readouterr().err.startswith(f"python -m studies.canonical.pooled: error: {tmp_path / 'run'}")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file", "run"]
