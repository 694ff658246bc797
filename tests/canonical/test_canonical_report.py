"""Canonical report: results.md layout (tables 5.1-5.4, thesis beside ours), contact sheets, mesh baselines."""
import json
from dataclasses import replace

import numpy as np
import pytest
import torch
from PIL import Image

from lit3d.canonical import report
from lit3d.utils.io import STAGE_PREFIX
from studies.canonical import report as report_program

SOURCES = ("model", "unet", "input", "target", "cmds", "smacof", "gps", "posed", "chance")


def _metrics():
    m = {"test/depth_mse": 0.0123, "test/iou": 0.81, "test/depth_mse_input": 0.0456, "test/iou_input": 0.52,
         "test/depth_mse_unet": 0.0234, "test/iou_unet": 0.71}
    for i, src in enumerate(SOURCES):
        for j, k in enumerate(("nn", "ft", "st", "e", "dcg")):
            m[f"test/retrieval/{src}/{k}"] = round(0.1 * (i % 9) + 0.01 * j, 4)
    for src in ("cmds", "smacof", "gps", "posed"):
        m[f"test/retrieval/{src}/seconds"] = 2.5
    return m


def _section(text, number):
    """The lines of the markdown section of table ``number`` (up to the next heading)."""
    part = text.split(f"## Table {number}:")[1].split("\n## ")[0]
    return "\n".join(line for line in part.splitlines() if line.startswith("|"))


def test_results_layout_thesis_beside_ours_in_the_matching_table(tmp_path):
    path = report.write_results(_metrics(), tmp_path, dataset="tosca")
    text = path.read_text()
    assert path == tmp_path / "results.md"
    # image metrics: model, U-Net and posed input rows with their numbers
    assert "| lit3d model (ours) | 0.0123 | 0.810 |" in text
    assert "| plain U-Net, same data and losses (ours) | 0.0234 | 0.710 |" in text
    assert "| posed input as its own canonical form (ours) | 0.0456 | 0.520 |" in text
    t53 = _section(text, "5.3")
    # thesis figures of table 5.3 and ours beside them: model row is source 0 -> nn .00 ft .01 st .02 dcg .04
    assert "| Constrained MDS (thesis) | 0.88 | 0.71 | 0.89 | 0.89 |" in t53
    assert "| Ours (thesis) | 0.91 | 0.76 | 0.80 | 0.89 |" in t53
    assert "| lit3d model (ours) | 0.00 | 0.01 | 0.02 | 0.04 |" in t53
    assert "| plain U-Net, same data and losses (ours) | 0.10 | 0.11 | 0.12 | 0.14 |" in t53
    assert "| classical MDS, full mesh (ours) | 0.40 | 0.41 | 0.42 | 0.44 |" in t53
    assert "| GPS, full mesh (ours) | 0.60 | 0.61 | 0.62 | 0.64 |" in t53
    assert "| chance: random distances (ours) | 0.80 | 0.81 | 0.82 | 0.84 |" in t53
    assert t53.count("(ours)") == len(SOURCES)
    # TOSCA run: our rows are not put into the SHREC'14 tables
    assert "(ours)" not in _section(text, "5.1") and "(ours)" not in _section(text, "5.2")
    assert "| Classic MDS (thesis) | 0.10 | 0.22 | 0.39 | 0.54 |" in _section(text, "5.1")
    assert "| without MSFE (thesis) | 0.72 | 0.48 | 0.61 | 0.73 |" in _section(text, "5.4")
    assert "cmds 2.5s" in text and "model 0.03, unet 0.13" in text
    assert "`task.arch=unet`" in text and "--unet UNET_RUN_DIR" in text  # how the U-Net rows are made


def test_the_outline_row_and_its_note_only_when_the_model_is_scored_on_its_outline(tmp_path):
    plain = report.write_results(_metrics(), tmp_path / "plain").read_text()
    m = {**_metrics(), "test/retrieval/input_outline/nn": 0.06, "test/retrieval/input_outline/ft": 0.09}
    text = report.write_results(m, tmp_path / "outline", dataset="synth").read_text()
    assert "scored on its outline" not in plain
    assert ("| posed input depth scored on its outline like the model row (evaluation.prediction_smooth_px) (ours) "
            "| 0.06 | 0.09 | – | – |") in _section(text, "5.1")
    assert "The model row is scored on its outline" in text


def test_results_dataset_from_run_config_and_missing_values(tmp_path):
    (tmp_path / "config.yaml").write_text("data:\n  source: synth\n")
    m = {"test/depth_mse": 0.02, "test/iou": 0.5, "test/retrieval/model/nn": 0.5, "test/retrieval/model/dcg": 0.7}
    text = report.write_results(m, tmp_path).read_text()
    t51 = _section(text, "5.1")
    assert "| lit3d model (ours) | 0.50 | – | – | 0.70 |" in t51
    assert "(ours)" not in _section(text, "5.3")
    assert "U-Net" not in text  # no U-Net trained: no U-Net rows
    assert "| posed input as its own canonical form (ours) | – | – |" in text
    # unknown data source: our rows go into every table
    other = tmp_path / "other"
    other.mkdir()
    text = report.write_results(m, other).read_text()
    assert all("lit3d model (ours)" in _section(text, n) for n in ("5.1", "5.2", "5.3"))
    # an evaluation writes into a staging folder inside the run dir: the run's source still picks the table
    (tmp_path / "config.yaml").write_text("data:\n  source: tosca\n")
    stage = tmp_path / f"{STAGE_PREFIX}123.abc.tmp"
    stage.mkdir()
    text = report.write_results(m, stage).read_text()
    assert "lit3d model (ours)" in _section(text, "5.3") and "(ours)" not in _section(text, "5.1")


def test_report_main_regenerates_from_metrics_json(tmp_path):
    (tmp_path / "metrics.json").write_text(json.dumps(_metrics()))
    report_program.main([str(tmp_path), "tosca"])
    assert "| lit3d model (ours) |" in _section((tmp_path / "results.md").read_text(), "5.3")


def test_report_main_merges_the_rows_of_a_unet_run(tmp_path):
    """The U-Net rows come from a plain U-Net run of its own (task.arch=unet): its image metrics
    and its retrieval (source "unet") are added by ``--unet``."""
    ours = {k: v for k, v in _metrics().items() if "unet" not in k}
    unet = {"test/depth_mse": 0.0234, "test/iou": 0.71, "test/depth_mse_input": 0.0456}
    unet.update({f"test/retrieval/unet/{k}": v for k, v in zip(("nn", "ft", "st", "e", "dcg"),
                                                                 (0.1, 0.11, 0.12, 0.13, 0.14))})
    unet.update({f"test/retrieval/input/{k}": 0.9 for k in ("nn", "ft", "st", "e", "dcg")})
    (tmp_path / "run").mkdir()
    (tmp_path / "unet").mkdir()
    (tmp_path / "run" / "metrics.json").write_text(json.dumps(ours))
    (tmp_path / "unet" / "metrics.json").write_text(json.dumps(unet))
    assert report_program.unet_run_metrics(unet) == {
        "test/depth_mse_unet": 0.0234, "test/iou_unet": 0.71,
        **{k: v for k, v in unet.items() if k.startswith("test/retrieval/unet/")}}
    report_program.main([str(tmp_path / "run"), "tosca", "--unet", str(tmp_path / "unet")])
    text = (tmp_path / "run" / "results.md").read_text()
    assert "| plain U-Net, same data and losses (ours) | 0.0234 | 0.710 |" in text
    t53 = _section(text, "5.3")
    assert "| plain U-Net, same data and losses (ours) | 0.10 | 0.11 | 0.12 | 0.14 |" in t53
    assert "| posed input depth, no canonicalisation (ours) | 0.20 | 0.21 | 0.22 | 0.24 |" in t53  # ours kept
    assert json.loads((tmp_path / "run" / "metrics.json").read_text()) == ours


def test_write_figures_one_contact_sheet_per_test_subject(tmp_path, compose_cfg):
    from omegaconf import OmegaConf

    from datamodules.canonical import CanonicalDataModule
    from lit3d.canonical.module import CanonicalTask

    S = 32
    dm = CanonicalDataModule.from_flat(str(tmp_path / "data"), image_size=S, n_subjects=6, n_poses=6, mesh_resolution=20,
                             n_folds=3, kinds=["humanoid"], seed=0)
    dm.prepare_data()
    dm.setup()
    torch.manual_seed(0)
    net = compose_cfg(["experiment=canonical_tiny", f"task.net.image_size={S}"]).task.net
    task = CanonicalTask(net=OmegaConf.to_container(net, resolve=True))
    out = tmp_path / "eval"
    out.mkdir()
    (out / "metrics.json").write_text(json.dumps(_metrics()))
    paths = report.write_figures(task, dm, out, n=3)
    test_subjects = sorted({r["subject"] for r in dm.splits["test"]})
    assert [p.name for p in paths] == [f"canonical_{s}.png" for s in test_subjects]
    from lit3d.canonical.figures import CELL, COLUMNS

    left, header = 170, 44
    for p, s in zip(paths, test_subjects):
        img = np.asarray(Image.open(p))
        rows = min(3, sum(r["subject"] == s for r in dm.splits["test"]))
        # labelled grid: title + header band, a label margin, one 256-px cell per column
        assert img.shape == (2 * header + rows * CELL, left + len(COLUMNS) * CELL, 3) and img.dtype == np.uint8
        # first cell = the posed input depth of the first test item of that subject, upsampled
        first = dm.datasets["test"][[i for i, r in enumerate(dm.splits["test"]) if r["subject"] == s][0]]
        expect = (first["depth"][0].clamp(0, 1).numpy() * 255).astype(np.uint8)
        k = CELL // S
        cell = img[2 * header:2 * header + CELL, left:left + CELL, 0]
        assert np.abs(cell[k // 2::k, k // 2::k].astype(int) - expect.astype(int)).max() <= 1
        # the shaded surface of the true canonical form is a rendered shape, not blank
        true_shaded = img[2 * header:2 * header + CELL, left + 4 * CELL:left + 5 * CELL]
        assert (true_shaded < 250).any(axis=2).mean() > 0.05 and np.ptp(true_shaded) > 50
    # results.md rewritten for the datamodule's source (synth -> table 5.1)
    text = (out / "results.md").read_text()
    assert "lit3d model (ours)" in _section(text, "5.1") and "(ours)" not in _section(text, "5.3")


def test_mesh_baseline_retrieval_separates_humanoids_from_quadrupeds():
    from datamodules.canonical import figures
    from lit3d.canonical.baselines import baseline_retrieval
    from lit3d.retrieval.descriptor import DescriptorConfig

    meshes, labels = [], []
    for label, kind in enumerate(("humanoid", "quadruped")):
        subj = figures.make_subject(kind, 3 + label)
        for pose in range(3):
            meshes.append(figures.figure_mesh(subj, figures.make_pose(kind, pose, 0, 1.0), 20))
            labels.append(label)
    cfg = DescriptorConfig(level=0, view_size=64, vocab=32, dense_step=6)
    res = baseline_retrieval(meshes, labels, ["cmds", "smacof", "gps", "posed"], cfg, max_vertices=300)
    assert set(res) == {"cmds", "smacof", "gps", "posed"}
    for method, s in res.items():
        assert {"nn", "ft", "st", "e", "dcg", "seconds"} <= set(s)
        assert all(0 <= s[k] <= 1 for k in ("nn", "ft", "st", "e", "dcg")), (method, s)
    # the posed full meshes of a humanoid and a quadruped are told apart by the descriptor: NN over
    # three codebook seeds (one seed alone moves NN by .33 on 6 items; measured 1.0, .67, .67) is
    # well above chance (2 of the 5 others relevant: .4). The canonical forms' pose invariance is
    # tested in test_canonical_retrieval_descriptor.
    nn = [res["posed"]["nn"]] + [
        baseline_retrieval(meshes, labels, ["posed"], replace(cfg, seed=seed), max_vertices=300)["posed"]["nn"]
        for seed in (1, 2)]
    assert np.mean(nn) >= 0.7, nn
    with pytest.raises(ValueError, match="unknown canonical baseline"):
        baseline_retrieval(meshes, labels, ["isomap"], cfg)
