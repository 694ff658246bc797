"""A canonical checkpoint of the flat layout (the task's and the data's settings as one flat mapping each, as
lit3d-train wrote them before the settings became config nodes) loads through every loader and predicts
what it predicted then: the API's load (and lit3d-reconstruct --canonical), lit3d-eval's reading, and
task.init_weights. The old hyper-parameters are written out here as the old code saved them (experiment
canonical_tiny with the identity classifier on), so the test needs no old code."""
import lightning
import pytest
import torch

from datamodules.canonical import CanonicalDataModule
from datamodules.canonical.flat_config import full_data_config, upgrade_data_config
from datamodules.canonical.settings import RenderSettings, SplitSettings, SynthSettings, TrainingSettings
from lit3d.api.checkpoints import load
from lit3d.canonical.checkpoint_upgrade import upgrade_checkpoint, upgrade_hparams, upgrade_net
from lit3d.canonical.factory import build_canonical_net
from lit3d.canonical.module import CanonicalTask
from lit3d.runtime.checkpoints import read_checkpoint
from lit3d.utils.checkpoints import META_KEY

NET = {"image_size": 48, "init": "he", "lfe_channels": [8, 12, 16], "lfe_out": 4, "msfe_channels": [6, 6, 4],
       "msfe_grid": 6, "fuser_hidden": 64, "fuser_out": 48, "msfe_dec_channels": [32, 16, 12, 8, 8, 8], "msfe_out": 4,
       "rec_channels": [12, 16, 24], "reconstruction": "downup", "head": "warp", "warp_hidden": 16,
       "warp_normalise_depth": False, "warp_depth": "affine", "warp_parts": 0, "warp_attend_grid": 0,
       "warp_refine_steps": 1, "warp_affine_cell": 8, "unet_channels": [16, 32, 64, 128],
       "recall_channels": [16, 32, 64, 128]}
# the same net in today's layout (the parked head options, at their defaults, dropped)
NET_NODES = {"image_size": 48, "init": "he", "lfe": {"use": True, "channels": [8, 12, 16], "out": 4},
             "msfe": {"use": True, "channels": [6, 6, 4], "grid": 6, "fuser_hidden": 64, "fuser_out": 48,
                      "dec_channels": [32, 16, 12, 8, 8, 8], "out": 4},
             "reconstruction": {"kind": "downup", "channels": [12, 16, 24]},
             "head": {"kind": "warp", "hidden": 16},
             "unet_channels": [16, 32, 64, 128], "recall_channels": [16, 32, 64, 128]}
# what the old code's net (seed 0, :func:`_inputs`) gave: sums of its parameters, of the predicted depth and mask
# probability (2, 1, 48, 48), and of the identity head's logits (2, 9) (torch.manual_seed(0) before the net, the
# head built after it)
OLD_SUMS = {"params": 9.28008754382688, "depth": 1923.2301972154528, "mask": 2700.064585539716,
            "identity": -2.7650357261300087}
# CanonicalTask's hyper-parameters as the flat layout saved them
OLD_HPARAMS = {
    "net": NET, "arch": "canonical", "use_lfe": True, "use_msfe": True, "lr": 0.001, "betas": [0.9, 0.999],
    "lr_schedule": "constant", "use_phases": True,
    "phases": [{"start": 0.0, "alpha": 10.0, "beta": 1000.0}, {"start": 0.125, "alpha": 1000.0, "beta": 1000.0},
               {"start": 0.375, "alpha": 1000.0, "beta": 100.0}],
    "phase_unit": "fraction", "alpha": 1000.0, "beta": 100.0, "mask_loss": "bce", "mask_threshold": 0.5,
    "image_every_n_epochs": 1, "n_panel": 4, "on_nonfinite": "raise", "identity_weight": 1.0, "identity_classes": 9,
    "init_weights": None, "flow_weight": 1000.0, "flow_on": "visible", "flow_power": 1.0, "vis_on": "foreground",
    "vis_weight": 100.0, "smooth_weight": 100.0, "offset_smooth_weight": 0.0, "depth_grad_weight": 0.0,
    "phenotype_weight": 0.0, "phenotype_dims": 6, "contrastive_weight": 0.0, "contrastive_on": "latent",
    "contrastive_temperature": 0.1, "contrastive_dim": 128, "contrastive_channels": [16, 32, 64, 128]}
# the DataModule's config as the flat layout saved it in the checkpoint's metadata
OLD_DATA = {
    "_target_": "datamodules.canonical.CanonicalDataModule", "source": "synth", "data_dir": "DATA/canonical_synth",
    "root": None, "image_size": 48, "kinds": ["humanoid"], "n_subjects": 9, "n_poses": 9, "mesh_resolution": 32,
    "pose_seed": 0, "yaw_range": 15.0, "pose_strength": 1.0, "pose_draw": "shared", "azimuths": [0.0],
    "view_mode": "fixed", "scale_mode": "shape", "split": "subject_pose", "n_folds": 3, "fold": 0,
    "val_per_subject": 1, "max_val_items": 64, "batch_size": 8, "num_workers": 0, "prepare_workers": 0, "seed": 42,
    "skip_bad": False, "balance_subjects": False, "batch_poses": 0, "flip_lr": False, "own_poses": 0,
    "blend_poses": 0, "train_pose_fraction": 1.0, "flow_targets": True, "forward_flow": False, "val_subjects": 2,
    "val_poses": "training"}
# its cache's config hash under the old code (the same cache is found again)
OLD_CONFIG_HASH = "1693a7e5bc048dfbcb504fdc82d3a3231b98c1c06b05ccf08621d4ed96b477f0"


def _inputs() -> tuple[torch.Tensor, torch.Tensor]:
    """A fixed posed depth and mask ``(2, 1, 48, 48)``."""
    g = torch.Generator().manual_seed(3)
    depth = torch.rand(2, 1, 48, 48, generator=g)
    mask = (depth > 0.4).float()
    return depth * mask, mask


@pytest.fixture
def old_checkpoint(tmp_path):
    """``(path, expected)``: a checkpoint file of the flat layout, and what its net and identity head give
    for :func:`_inputs` (``depth``, ``mask`` ``(2, 1, 48, 48)``, identity logits ``(2, 9)``), as the old code's
    (:data:`OLD_SUMS`)."""
    torch.manual_seed(0)
    net = build_canonical_net({**NET_NODES, "kind": "canonical"}).eval()
    head = torch.nn.Linear(48, 9)
    assert float(sum(p.detach().double().sum() for p in net.parameters())) == pytest.approx(OLD_SUMS["params"], rel=1e-9)
    state = {**{f"net.{k}": v for k, v in net.state_dict().items()},
             **{f"identity_head.{k}": v for k, v in head.state_dict().items()}}
    with torch.no_grad():
        out = net(*_inputs())
        expected = {"depth": out.depth, "mask": out.mask, "identity": head(out.latent)}
    for k, v in expected.items():  # the old code's prediction
        assert float(v.double().sum()) == pytest.approx(OLD_SUMS[k], rel=1e-6), k
    task_cfg = {"name": "canonical", "monitor": "val/depth_mse", "monitor_mode": "min",
                "_target_": "lit3d.canonical.module.CanonicalTask", **OLD_HPARAMS}
    ckpt = {"state_dict": state, "hyper_parameters": OLD_HPARAMS, "epoch": 1, "global_step": 6,
            "pytorch-lightning_version": lightning.__version__,
            META_KEY: {"task": task_cfg, "data": OLD_DATA, "wandb_id": None}}
    path = tmp_path / "old.ckpt"
    torch.save(ckpt, path)
    return path, expected


def _predict(task: CanonicalTask) -> dict[str, torch.Tensor]:
    task.eval()
    with torch.no_grad():
        out = task(*_inputs())
        return {"depth": out.depth, "mask": out.mask, "identity": task.identity_head(out.latent)}


def _same(got: dict, expected: dict) -> None:
    for k, v in expected.items():
        assert torch.equal(got[k], v), k


def test_flat_hparams_become_the_nodes():
    new = upgrade_hparams(OLD_HPARAMS)
    assert new == {
        "net": NET_NODES, "arch": "canonical", "mask_loss": "bce",
        "mask_threshold": 0.5, "on_nonfinite": "raise", "init_weights": None,
        "optimizer": {"lr": 0.001, "betas": [0.9, 0.999], "schedule": "constant"},
        "phases": {"use": True, "weights": OLD_HPARAMS["phases"], "unit": "fraction", "alpha": 1000.0, "beta": 100.0},
        "panels": {"every_n_epochs": 1, "n": 4},
        "identity": {"weight": 1.0, "classes": 9},
        "warp": {"flow_weight": 1000.0, "vis_weight": 100.0, "smooth_weight": 100.0}}
    assert upgrade_hparams(new) == new and upgrade_net(NET_NODES) == NET_NODES  # today's layout: unchanged
    # evaluation settings that older checkpoints hold among the hyper-parameters leave them (lit3d-eval reads
    # them from the task config, where they stay)
    assert "chance_trials" not in upgrade_hparams({**OLD_HPARAMS, "chance_trials": 11})
    assert upgrade_hparams({**OLD_HPARAMS, "chance_trials": 11}, keep_evaluation=True)["chance_trials"] == 11


def test_the_api_loads_it_and_predicts_as_before(old_checkpoint):
    path, expected = old_checkpoint
    mapper = load(str(path))  # lit3d.load; lit3d-reconstruct --canonical loads through the same load_task
    _same(_predict(mapper.task), expected)
    assert mapper.task.identity.classes == 9 and mapper.task.warp.flow_weight == 1000.0


def test_lit3d_eval_reads_it_in_todays_layout_and_predicts_as_before(old_checkpoint):
    path, expected = old_checkpoint
    ckpt, meta = read_checkpoint(path)
    assert "identity" in ckpt["hyper_parameters"] and "identity_weight" not in meta["task"]
    assert meta["task"]["name"] == "canonical" and meta["task"]["optimizer"]["lr"] == 0.001
    task = CanonicalTask.load_from_checkpoint(path, map_location="cpu", weights_only=True, **ckpt["hyper_parameters"])
    _same(_predict(task), expected)
    data = {k: v for k, v in meta["data"].items() if k != "_target_"}
    dm = CanonicalDataModule(**data)
    assert dm.source_settings == SynthSettings(kinds=("humanoid",), n_subjects=9, n_poses=9, mesh_resolution=32, seed=42)
    assert dm.render == RenderSettings(flow_targets=True)
    assert dm.split == SplitSettings(val_subjects=2)
    assert dm.training == TrainingSettings()
    assert dm.config_hash() == OLD_CONFIG_HASH  # the same cache as before
    assert dm.seed == 42  # the split's seed too


def test_the_flat_seed_stays_the_datamodules_and_draws_the_figures():
    new = upgrade_data_config({**OLD_DATA, "seed": 7})
    assert new["seed"] == 7 and new["source"]["seed"] == 7
    assert upgrade_data_config(new) == new


def test_a_flat_data_config_and_its_nodes_spell_out_alike():
    """heldout.npz files of either layout pool together: their data configs compare spelt out."""
    written = {"_target_": OLD_DATA["_target_"], "data_dir": OLD_DATA["data_dir"], "image_size": 48, "seed": 42,
               "source": {"kind": "synth", "kinds": ["humanoid"], "n_subjects": 9, "n_poses": 9,
                          "mesh_resolution": 32},
               "render": {"flow_targets": True}, "split": {"val_subjects": 2}}
    assert full_data_config(OLD_DATA) == full_data_config(written)
    assert full_data_config({**OLD_DATA, "fold": 1}) != full_data_config(written)


def test_init_weights_starts_from_its_net(old_checkpoint):
    path, expected = old_checkpoint
    task = CanonicalTask(**{**upgrade_hparams(OLD_HPARAMS), "init_weights": str(path)})
    task.load_initial_weights(str(path))
    got = _predict(task)
    assert torch.equal(got["depth"], expected["depth"]) and torch.equal(got["mask"], expected["mask"])


def test_a_checkpoint_of_another_task_is_left_alone():
    ckpt = {"hyper_parameters": {"lr": 1.0}, META_KEY: {"task": {"name": "completion"}, "data": {"source": "synth"}}}
    assert upgrade_checkpoint(ckpt) == {"hyper_parameters": {"lr": 1.0},
                                        META_KEY: {"task": {"name": "completion"}, "data": {"source": "synth"}}}


def _with(ckpt_path, tmp_path, edit) -> str:
    """A copy of the checkpoint at ``ckpt_path`` with ``edit(ckpt)`` applied, saved as ``tmp_path/parked.ckpt``."""
    ckpt = torch.load(ckpt_path, map_location="cpu", weights_only=False)
    edit(ckpt)
    path = tmp_path / "parked.ckpt"
    torch.save(ckpt, path)
    return str(path)


@pytest.mark.parametrize("flat,key,value", [("warp_parts", "task.net.head.parts", 8),
                                            ("warp_depth", "task.net.head.depth", "offset"),
                                            ("head", "task.net.head.kind", "splat"),
                                            ("contrastive_weight", "task.contrastive.weight", 10.0),
                                            ("flow_on", "task.warp.flow_on", "image")])
def test_a_checkpoint_that_used_a_parked_option_is_refused_naming_file_key_and_tag(old_checkpoint, tmp_path, flat,
                                                                                  key, value):
    from lit3d.runtime.errors import UserError

    def edit(ckpt):
        for hp in (ckpt["hyper_parameters"], ckpt[META_KEY]["task"]):
            (hp["net"] if flat in hp["net"] else hp)[flat] = value
    path = _with(old_checkpoint[0], tmp_path, edit)
    with pytest.raises(UserError, match=rf"^{path}: {key}={value!r} is a parked canonical option .*parked-canonical-options$"):
        read_checkpoint(path)
    with pytest.raises(ValueError, match=rf"{path}: {key}="):
        CanonicalTask(net=NET_NODES, identity={"weight": 1.0, "classes": 9}).load_initial_weights(path)


@pytest.mark.parametrize("flat,key,value", [("batch_poses", "data.training.batch_poses", 4),
                                            ("forward_flow", "data.render.forward_flow", True),
                                            ("phenotype_targets", "data.phenotype_targets", True)])
def test_a_checkpoint_that_used_a_parked_data_option_is_refused_naming_file_key_and_tag(old_checkpoint, tmp_path, flat,
                                                                                       key, value):
    from lit3d.runtime.errors import UserError

    path = _with(old_checkpoint[0], tmp_path, lambda c: c[META_KEY]["data"].update({flat: value}))
    with pytest.raises(UserError, match=rf"^{path}: {key}={value!r} is a parked canonical option .*parked-canonical-options$"):
        read_checkpoint(path)
    with pytest.raises(ValueError, match=rf"^{path}: {key}={value!r} is a parked"):
        upgrade_checkpoint(torch.load(path, weights_only=False), path)


# the same data in the layout of nodes as lit3d-train wrote it before the parked data options left (run configs,
# checkpoints and heldout.npz files of that time hold them at their defaults)
NODES_WITH_PARKED = {"data_dir": "DATA/canonical_synth", "image_size": 48, "seed": 42, "phenotype_targets": False,
                     "source": {"kind": "synth", "kinds": ["humanoid"], "n_subjects": 9, "n_poses": 9,
                                "mesh_resolution": 32, "seed": 42},
                     "render": {"flow_targets": True, "forward_flow": False},
                     "split": {"val_subjects": 2}, "training": {"flip_lr": False, "batch_poses": 0}}


def test_a_config_of_nodes_loses_the_parked_data_options_at_their_defaults():
    data = upgrade_data_config(NODES_WITH_PARKED)
    assert "phenotype_targets" not in data and data["render"] == {"flow_targets": True}
    assert data["training"] == {"flip_lr": False}
    assert CanonicalDataModule(**data).config_hash() == OLD_CONFIG_HASH  # the same cache as before
    written = {"_target_": OLD_DATA["_target_"], **NODES_WITH_PARKED}
    assert full_data_config(written) == full_data_config(OLD_DATA)  # heldout.npz files of either layout still pool


@pytest.mark.parametrize("node,key,value", [("render", "forward_flow", True), ("training", "batch_poses", 2),
                                            (None, "phenotype_targets", True)])
def test_a_config_of_nodes_that_used_a_parked_data_option_is_refused(node, key, value):
    cfg = {**NODES_WITH_PARKED, **({key: value} if node is None else {node: {**NODES_WITH_PARKED[node], key: value}})}
    dotted = f"data.{key}" if node is None else f"data.{node}.{key}"
    with pytest.raises(ValueError, match=rf"^run/heldout.npz: {dotted}={value!r} is a parked canonical option .*"
                                         r"git tag parked-canonical-options$"):
        full_data_config(cfg, "run/heldout.npz")
    with pytest.raises(ValueError, match=rf"^{dotted}={value!r} is a parked"):
        upgrade_data_config(cfg)


def test_an_offset_depth_head_is_refused(old_checkpoint, tmp_path):
    def offset_head(ckpt):  # a warp head from before task.net.head.depth: flow 2 + offset 1 + vis and fills 3
        ckpt["state_dict"]["net.head.out.weight"] = torch.zeros(6, 16, 1, 1)
        for hp in (ckpt["hyper_parameters"], ckpt[META_KEY]["task"]):
            hp["net"].pop("warp_depth", None)  # (one dict in both places after torch.load)
    path = _with(old_checkpoint[0], tmp_path, offset_head)
    with pytest.raises(ValueError, match=rf"^{path}: task.net.head.depth='offset' is a parked"):
        upgrade_checkpoint(torch.load(path, weights_only=False), path)


def test_parked_options_at_their_defaults_are_dropped_from_every_node(old_checkpoint):
    ckpt = upgrade_checkpoint(torch.load(old_checkpoint[0], weights_only=False))
    for hp in (ckpt["hyper_parameters"], ckpt[META_KEY]["task"]):
        assert hp["net"]["head"] == {"kind": "warp", "hidden": 16}
        assert "phenotype" not in hp and "contrastive" not in hp and set(hp["warp"]) == {"flow_weight", "vis_weight",
                                                                                          "smooth_weight"}
    assert "batch_poses" not in ckpt[META_KEY]["data"]["training"]
    assert "forward_flow" not in ckpt[META_KEY]["data"]["render"]
