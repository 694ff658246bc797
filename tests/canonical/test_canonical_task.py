"""Canonical task: short real training beats the posed-input baseline on held-out subjects and poses;
retrieval and the mesh baselines come from the evaluator's protocol after the test."""
import time
from types import SimpleNamespace

import lightning.pytorch as pl
import pytest
import torch

from datamodules.canonical import CanonicalDataModule
from omegaconf import OmegaConf

from lit3d.canonical import evaluator
from lit3d.canonical.checkpoint_upgrade import upgrade_hparams
from lit3d.canonical.module import CanonicalTask, validation_retrieval
from lit3d.canonical.warp_loss import warp_terms
from lit3d.runtime.build import build_datamodule, build_task


@pytest.fixture
def one_thread():
    n = torch.get_num_threads()
    torch.set_num_threads(1)  # 2 shared cores: one thread is several times faster than two here
    yield
    torch.set_num_threads(n)


@pytest.fixture
def tiny_net(compose_cfg):
    """tiny_net(size) -> the net sizes of experiment=canonical_tiny at ``size``^2 (plain dict)."""
    def net(size: int = 48) -> dict:
        cfg = compose_cfg(["experiment=canonical_tiny", f"task.net.image_size={size}"])
        return OmegaConf.to_container(cfg.task.net, resolve=True)
    return net


def _settings(retrieval=None, mesh_baselines=None, baseline_max_vertices=None) -> dict:
    """Evaluation settings (the config's ``evaluation`` node) with 20 chance trials."""
    return {"retrieval": retrieval, "retrieval_min_subjects": 2, "chance_trials": 20, "ceiling_jitter_deg": 0.0,
            "mesh_baselines": mesh_baselines, "baseline_max_vertices": baseline_max_vertices,
            "baseline_landmarks": 300, "baseline_smacof_eps": 1e-4}


def _train(tmp_path, net, epochs, retrieval=None, size=48, n=9, mesh_resolution=32, mesh_baselines=None,
           baseline_max_vertices=None, **task_kw):
    """Fit and test on synthetic humanoids; returns (task, datamodule, test metrics + evaluator protocol
    with the evaluation settings ``retrieval``, ``mesh_baselines``, ``baseline_max_vertices``)."""
    pl.seed_everything(0, workers=True)
    dm = CanonicalDataModule.from_flat(str(tmp_path / "data"), image_size=size, n_subjects=n, n_poses=n,
                             mesh_resolution=mesh_resolution, n_folds=3, batch_size=8, kinds=["humanoid"], seed=0)
    task = CanonicalTask(net=net(size), **task_kw)
    settings = _settings(retrieval, mesh_baselines, baseline_max_vertices)
    tr = pl.Trainer(max_epochs=epochs, logger=False, enable_checkpointing=False, enable_progress_bar=False,
                    enable_model_summary=False, accelerator="cpu", num_sanity_val_steps=0,
                    check_val_every_n_epoch=epochs, deterministic=True)
    tr.fit(task, dm)
    validation = {k: float(v) for k, v in tr.callback_metrics.items() if k.startswith("val/")}  # test() clears them
    res = tr.test(task, dm, verbose=False)[0] | validation
    res.update(evaluator.protocol(task, dm, settings).metrics)
    return task, dm, res


# about 35 s on 2 cores: in the default suite (the task's beat-the-baseline run)
def test_short_training_beats_posed_input_on_held_out_subjects_and_poses(tmp_path, one_thread, tiny_net):
    t0 = time.time()
    task, dm, res = _train(tmp_path, tiny_net, epochs=20, mask_loss="bce",
                           retrieval={"level": 0, "view_size": 48, "vocab": 32, "dense_step": 6})
    assert {r["subject"] for r in dm.splits["test"]}.isdisjoint({r["subject"] for r in dm.splits["train"]})
    assert res["test/depth_mse"] < 0.9 * res["test/depth_mse_input"], res  # measured 0.170 vs 0.214
    assert res["test/iou"] > res["test/iou_input"] + 0.04, res  # measured 0.491 vs 0.403
    for src in ("model", "input", "target", "chance"):
        assert 0 <= res[f"test/retrieval/{src}/dcg"] <= 1
    assert task.loss_alpha == 1000 and task.loss_beta == 100  # last phase reached
    for k in ("retrieval_nn", "retrieval_ft", "retrieval_nn_input", "retrieval_ft_input"):  # validation subjects
        assert 0 <= res[f"val/{k}"] <= 1, (k, res)  # retrieved by mask IoU, every validation epoch
    print(f"train+test {time.time() - t0:.0f}s: {res}")


def test_tiny_run_scores_mesh_baselines_and_a_unet_run_under_its_source(tmp_path, one_thread, tiny_net):
    """Fast twin of the test above: two epochs at 32^2 with the non-learned mesh baselines computed
    by the evaluator after the test; then a plain U-Net run (arch=unet) on the same data, whose
    retrieval is scored under source "unet". Checks what is reported, not the quality."""
    kw = dict(epochs=2, size=32, n=6, mesh_resolution=20, mask_loss="bce",
              retrieval={"level": 0, "view_size": 32, "vocab": 16, "dense_step": 6})
    task, dm, res = _train(tmp_path, tiny_net, mesh_baselines=["cmds", "smacof", "gps", "posed"],
                           baseline_max_vertices=200, **kw)
    for k in ("depth_mse", "iou", "depth_mse_input", "iou_input"):
        assert torch.isfinite(torch.tensor(res[f"test/{k}"])), k
    for src in ("model", "input", "target", "chance", "cmds", "smacof", "gps", "posed"):
        for k in ("nn", "ft", "st", "e", "dcg"):
            assert 0 <= res[f"test/retrieval/{src}/{k}"] <= 1, (src, k)
    assert res["test/retrieval/target/nn"] >= res["test/retrieval/chance/nn"]
    assert res["test/retrieval/cmds/seconds"] > 0
    # the gathered test outputs hold every test item once; the mesh baselines rank one item per
    # unique test (subject, pose)
    outputs = {k: v.cpu() for k, v in task.test_outputs.compute().items()}
    assert outputs["pred_depth"].shape == (len(dm.splits["test"]), 1, 32, 32)
    n_shapes = len({(r["subject"], r["pose"]) for r in dm.splits["test"]})
    results = evaluator.retrieval_results(_settings(kw["retrieval"], ["cmds"], 200), outputs, dm)
    assert results["cmds"]["n_queries"] <= n_shapes
    # the plain U-Net as a run of its own: same data and losses, retrieval under source "unet"
    unet, _, res_u = _train(tmp_path, tiny_net, arch="unet", **kw)
    assert type(unet.net).__name__ == "UNet"
    for src in ("unet", "input", "target", "chance"):
        for k in ("nn", "ft", "st", "e", "dcg"):
            assert 0 <= res_u[f"test/retrieval/{src}/{k}"] <= 1, (src, k)
    assert not any(k.startswith("test/retrieval/model/") for k in res_u)


def test_config_builds_task_and_data(compose_cfg):
    cfg = compose_cfg(["experiment=canonical_demo"])
    task = build_task(cfg.task)
    assert isinstance(task, CanonicalTask) and task.net.lfe is not None and task.phases.use
    dm = build_datamodule(cfg.data)
    assert isinstance(dm, CanonicalDataModule) and dm.hparams.image_size == 64 and dm.split.val_poses == "own"
    off = compose_cfg(["experiment=canonical_demo", "task.net.lfe.use=false", "task.phases.use=false"])
    t2 = build_task(off.task)
    assert t2.net.lfe is None and t2.configure_callbacks() == []


def test_paper_summary_rows():
    from lit3d.runtime.build import task_kwargs

    GlobalCfg = None  # noqa: F841
    from hydra import compose, initialize_config_dir

    from lit3d.runtime.compose import CONF_DIR

    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        cfg = compose(config_name="train", overrides=["experiment=canonical_paper"])
    with torch.device("meta"):
        rows = CanonicalTask.summary_rows(task_kwargs(cfg.task))
    by = {r["name"]: r for r in rows}
    assert by["MSFE encoder d=1"]["output_shape"] == (1, 16000)
    assert by["MSFE fuser"]["output_shape"] == (1, 500)
    assert by["total"]["output_shape"] == (1, 2, 500, 500)


def test_checkpoint_loads_with_weights_only(tmp_path, tiny_net):
    task = CanonicalTask(net=tiny_net())
    tr = pl.Trainer(max_epochs=1, logger=False, accelerator="cpu", enable_progress_bar=False)
    tr.strategy.connect(task)
    path = tmp_path / "c.ckpt"
    tr.save_checkpoint(path)
    ckpt = torch.load(path, weights_only=True)
    assert ckpt["hyper_parameters"]["net"]["image_size"] == 48
    again = CanonicalTask.load_from_checkpoint(path, map_location="cpu", weights_only=True)
    assert isinstance(again, CanonicalTask)
    # checkpoints written before the U-Net became a run of its own carry unet_baseline=False
    ckpt["hyper_parameters"]["unet_baseline"] = False
    torch.save(ckpt, tmp_path / "old.ckpt")
    assert isinstance(CanonicalTask.load_from_checkpoint(tmp_path / "old.ckpt", map_location="cpu",
                                                         weights_only=True), CanonicalTask)
    with pytest.raises(ValueError, match="task.arch=unet"):  # a checkpoint with the removed baseline switch on
        upgrade_hparams({"net": tiny_net(), "unet_baseline": True})


def test_fine_tuning_starts_from_the_pretrained_net(tmp_path, tiny_net):
    """init_weights: a fresh fit starts from the checkpoint's net (one training step from there moves
    little; a random start is far), and a checkpoint of other net sizes is one error naming it."""
    torch.manual_seed(1)
    pre = CanonicalTask(net=tiny_net())
    torch.manual_seed(2)  # the tasks below start from another random draw
    tr = pl.Trainer(max_epochs=1, logger=False, accelerator="cpu", enable_progress_bar=False)
    tr.strategy.connect(pre)
    tr.save_checkpoint(tmp_path / "pre.ckpt")
    dm = CanonicalDataModule.from_flat(str(tmp_path / "data"), image_size=48, n_subjects=6, n_poses=6, mesh_resolution=32,
                             n_folds=3, batch_size=4, kinds=["humanoid"], seed=0)
    tuned = CanonicalTask(net=tiny_net(), init_weights=str(tmp_path / "pre.ckpt"), mask_loss="bce",
                          optimizer={"lr": 1e-5})
    fresh = CanonicalTask(net=tiny_net(), mask_loss="bce", optimizer={"lr": 1e-5})
    for task in (tuned, fresh):
        pl.Trainer(max_epochs=1, limit_train_batches=1, logger=False, enable_checkpointing=False, enable_progress_bar=False,
                   enable_model_summary=False, accelerator="cpu", num_sanity_val_steps=0,
                   limit_val_batches=0).fit(task, dm)

    def gap(task):
        return max(float((a - b).detach().abs().max()) for a, b in zip(task.net.parameters(), pre.net.parameters()))

    assert gap(tuned) < 1e-3 < 0.05 < gap(fresh)  # Adam at lr 1e-5: one step moves a weight by about 1e-5
    net = tiny_net()
    other = {**net, "lfe": {**net["lfe"], "out": net["lfe"]["out"] + 1}}
    with pytest.raises(ValueError, match=r"pre\.ckpt: not a pretrained net for this one"):
        CanonicalTask(net=other).load_initial_weights(str(tmp_path / "pre.ckpt"))


def test_warp_terms_join_the_loss_with_their_weights(tiny_net):
    """The warp head's terms, flow, visibility and smoothness, each times its weight."""
    torch.manual_seed(0)
    net = tiny_net()
    kw = dict(net={**net, "head": {**net["head"], "kind": "warp"}}, phases={"use": False, "alpha": 1.0, "beta": 1.0},
              warp={"flow_weight": 2.0, "vis_weight": 3.0, "smooth_weight": 4.0})
    batch = {"depth": torch.rand(2, 1, 48, 48), "canon_depth": torch.rand(2, 1, 48, 48),
             "flow": torch.randn(2, 2, 48, 48), "has_flow": torch.tensor([True, False])}
    batch["mask"] = (batch["depth"] > 0.3).float()
    batch["canon_mask"] = (batch["canon_depth"] > 0.3).float()
    batch["vis"] = batch["canon_mask"].clone()
    batch["subject_idx"] = torch.tensor([0, 1])
    base = CanonicalTask(**kw)
    torch.nn.init.normal_(base.net.head.out.weight, std=0.1)  # a non-zero flow and depth map
    base.log = base.log_dict = lambda *a, **k: None  # a direct training_step call logs nowhere
    out = base.net(batch["depth"], batch["mask"])
    terms = {k: v.detach() for k, v in warp_terms(out, batch).items()}
    from lit3d.canonical.losses import canonical_loss

    image = canonical_loss(out.depth, out.mask, batch["canon_depth"], batch["canon_mask"], 1.0, 1.0, "mse",
                           out.mask_logits)["loss"]
    expected = image.detach() + 2.0 * terms["flow"] + 3.0 * terms["vis"] + 4.0 * terms["smooth"]
    assert float(base.training_step(batch, 0).detach()) == pytest.approx(float(expected), rel=1e-5)
    assert all(float(terms[k]) > 0 for k in ("flow", "vis", "smooth"))


def test_validation_retrieval_finds_each_subject_by_its_mask():
    """Three subjects, two items each: predictions that keep each subject's own width are retrieved
    perfectly; posed inputs that are all one body are retrieved at the tie level."""
    pred = torch.zeros(6, 1, 16, 16, dtype=torch.bool)
    for i, width in enumerate((2, 2, 5, 5, 9, 9)):
        pred[i, 0, 2:14, 3:3 + width] = True
    same = torch.zeros_like(pred)
    same[:, 0, 2:14, 3:8] = True
    out = validation_retrieval({"pred_mask": pred, "mask": same, "subject_idx": torch.tensor([0, 0, 1, 1, 2, 2])})
    assert out["retrieval_nn"] == out["retrieval_ft"] == 1.0
    assert out["retrieval_nn_input"] == pytest.approx(0.2)  # 1 of 5 tied others is the subject's
    assert validation_retrieval({"pred_mask": pred[::2], "mask": same[::2], "subject_idx": torch.arange(3)}) == {}


def test_cosine_schedule_falls_to_zero_over_the_runs_steps(tiny_net):
    task = CanonicalTask(net=tiny_net(), optimizer={"lr": 2e-3, "schedule": "cosine"})
    task._trainer = SimpleNamespace(estimated_stepping_batches=10)  # what Lightning counts for the fit
    cfg = task.configure_optimizers()
    opt, sched = cfg["optimizer"], cfg["lr_scheduler"]["scheduler"]
    assert cfg["lr_scheduler"]["interval"] == "step"
    rates = []
    for _ in range(10):
        rates.append(opt.param_groups[0]["lr"])
        opt.step()
        sched.step()
    assert rates[0] == pytest.approx(2e-3) and rates[5] == pytest.approx(1e-3)  # half-way: half the rate
    assert all(a > b for a, b in zip(rates, rates[1:])) and opt.param_groups[0]["lr"] == pytest.approx(0, abs=1e-12)
    constant = CanonicalTask(net=tiny_net(), optimizer={"lr": 2e-3}).configure_optimizers()
    assert isinstance(constant, torch.optim.Adam)
    with pytest.raises(ValueError, match="task.optimizer.schedule"):
        CanonicalTask(net=tiny_net(), optimizer={"schedule": "linear"})
