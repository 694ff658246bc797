"""Canonical task: short real training beats the posed-input baseline on held-out subjects and poses."""
import time

import lightning.pytorch as pl
import pytest
import torch

from datamodules.canonical import CanonicalDataModule
from lit3d.cli.common import build_datamodule, build_task
from lit3d.nets.canonical import TINY
from lit3d.tasks.canonical import CanonicalTask


@pytest.fixture
def one_thread():
    n = torch.get_num_threads()
    torch.set_num_threads(1)  # 2 shared cores: one thread is several times faster than two here
    yield
    torch.set_num_threads(n)


def _train(tmp_path, epochs, retrieval=None, size=48, n=9, mesh_resolution=32, **task_kw):
    pl.seed_everything(0, workers=True)
    dm = CanonicalDataModule(str(tmp_path / "data"), image_size=size, n_subjects=n, n_poses=n,
                             mesh_resolution=mesh_resolution, n_folds=3, batch_size=8, kinds=["humanoid"], seed=0)
    task = CanonicalTask(net={**TINY, "image_size": size}, retrieval=retrieval, chance_trials=20, **task_kw)
    tr = pl.Trainer(max_epochs=epochs, logger=False, enable_checkpointing=False, enable_progress_bar=False,
                    enable_model_summary=False, accelerator="cpu", num_sanity_val_steps=0,
                    check_val_every_n_epoch=epochs, deterministic=True)
    tr.fit(task, dm)
    res = tr.test(task, dm, verbose=False)[0]
    return task, dm, res


# about 35 s on 2 cores: in the default suite (the task's beat-the-baseline run)
def test_short_training_beats_posed_input_on_held_out_subjects_and_poses(tmp_path, one_thread):
    t0 = time.time()
    task, dm, res = _train(tmp_path, epochs=20, mask_loss="bce",
                           retrieval={"level": 0, "view_size": 48, "vocab": 32, "dense_step": 6})
    assert {r["subject"] for r in dm.splits["test"]}.isdisjoint({r["subject"] for r in dm.splits["train"]})
    assert res["test/depth_mse"] < 0.9 * res["test/depth_mse_input"], res  # measured 0.170 vs 0.214
    assert res["test/iou"] > res["test/iou_input"] + 0.04, res  # measured 0.491 vs 0.403
    for src in ("model", "input", "target", "chance"):
        assert 0 <= res[f"test/retrieval/{src}/dcg"] <= 1
    assert task.loss_alpha == 1000 and task.loss_beta == 100  # last phase reached
    print(f"train+test {time.time() - t0:.0f}s: {res}")


def test_tiny_run_logs_unet_and_mesh_baselines_beside_the_model(tmp_path, one_thread):
    """Fast twin of the test above: two epochs at 32^2 with the U-Net trained in the same run and the
    non-learned mesh baselines computed at test time; checks what is logged, not the quality."""
    task, dm, res = _train(tmp_path, epochs=2, size=32, n=6, mesh_resolution=20, mask_loss="bce",
                           retrieval={"level": 0, "view_size": 32, "vocab": 16, "dense_step": 6},
                           unet_baseline=True, mesh_baselines=["cmds", "smacof", "gps", "posed"],
                           baseline_max_vertices=200)
    assert task.unet is not None and type(task.unet).__name__ == "UNet"
    for k in ("depth_mse", "iou", "depth_mse_input", "iou_input", "depth_mse_unet", "iou_unet"):
        assert torch.isfinite(torch.tensor(res[f"test/{k}"])), k
    for src in ("model", "unet", "input", "target", "chance", "cmds", "smacof", "gps", "posed"):
        for k in ("nn", "ft", "st", "e", "dcg"):
            assert 0 <= res[f"test/retrieval/{src}/{k}"] <= 1, (src, k)
    assert res["test/retrieval/target/nn"] >= res["test/retrieval/chance/nn"]
    assert res["test/retrieval/cmds/seconds"] > 0
    # the mesh baselines rank one item per unique test (subject, pose)
    n_shapes = len({(r["subject"], r["pose"]) for r in dm.splits["test"]})
    assert task.retrieval_results["cmds"]["n_queries"] <= n_shapes


def test_config_builds_task_and_data(compose_cfg):
    cfg = compose_cfg(["experiment=canonical_demo"])
    task = build_task(cfg.task)
    assert isinstance(task, CanonicalTask) and task.hparams.use_lfe and task.hparams.use_phases
    dm = build_datamodule(cfg.data)
    assert isinstance(dm, CanonicalDataModule) and dm.hparams.image_size == 128
    off = compose_cfg(["experiment=canonical_demo", "task.use_lfe=false", "task.use_phases=false"])
    t2 = build_task(off.task)
    assert t2.net.lfe is None and t2.configure_callbacks() == []


def test_paper_summary_rows():
    from lit3d.cli.common import task_kwargs

    GlobalCfg = None  # noqa: F841
    from hydra import compose, initialize_config_dir

    from lit3d.cli.common import CONF_DIR

    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        cfg = compose(config_name="train", overrides=["experiment=canonical_paper"])
    with torch.device("meta"):
        rows = CanonicalTask.summary_rows(task_kwargs(cfg.task))
    by = {r["name"]: r for r in rows}
    assert by["MSFE encoder d=1"]["output_shape"] == (1, 16000)
    assert by["MSFE fuser"]["output_shape"] == (1, 500)
    assert by["total"]["output_shape"] == (1, 2, 500, 500)


def test_checkpoint_loads_with_weights_only(tmp_path):
    task = CanonicalTask(net=dict(TINY))
    tr = pl.Trainer(max_epochs=1, logger=False, accelerator="cpu", enable_progress_bar=False)
    tr.strategy.connect(task)
    path = tmp_path / "c.ckpt"
    tr.save_checkpoint(path)
    ckpt = torch.load(path, weights_only=True)
    assert ckpt["hyper_parameters"]["net"]["image_size"] == 48
    again = CanonicalTask.load_from_checkpoint(path, map_location="cpu", weights_only=True)
    assert isinstance(again, CanonicalTask)
