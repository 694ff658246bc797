"""Canonical checkpoints written before the task's and the data's settings became config nodes, read as
today's: the one place that knows the old layouts.

:func:`upgrade_checkpoint` rewrites a loaded checkpoint dict in place and returns it: its
``hyper_parameters`` (:func:`upgrade_hparams`) and, in its lit3d metadata, the task config and the data
config (:func:`datamodules.canonical.flat_config.upgrade_data_config`); the parked options (:data:`PARKED`, and
the data's :data:`datamodules.canonical.parked.PARKED_DATA`: measured and not adopted, removed; their code is at
the git tag :data:`datamodules.canonical.parked.PARKED_TAG`) dropped where they hold their default, and the
checkpoint refused where one does not. A checkpoint of today's layout, or of another task, comes back unchanged.
Every loader of a canonical checkpoint calls it: ``lit3d-eval`` (:func:`lit3d.runtime.checkpoints.read_checkpoint`),
the API and ``lit3d-reconstruct --canonical`` (:func:`lit3d.reconstruct.pipeline.load_task`) and
``task.init_weights`` (:meth:`lit3d.canonical.module.CanonicalTask.load_initial_weights`).
"""
from __future__ import annotations

from collections.abc import Mapping

from datamodules.canonical.flat_config import upgrade_data_config
from datamodules.canonical.parked import ANY, drop_parked, refuse
from lit3d.utils.checkpoints import META_KEY

TASK_TARGET = "lit3d.canonical.module.CanonicalTask"

# the evaluator's settings (the config's ``evaluation`` node, :func:`lit3d.canonical.evaluator.protocol`) that
# checkpoints written before that node hold among the task's hyper-parameters, with the defaults the
# constructor had for them then (what such a checkpoint without the key was evaluated with); they stay in the
# checkpoint's task config, where ``lit3d-eval`` reads them (:mod:`lit3d.runtime.eval_settings`)
EVALUATION_LEGACY = {"retrieval": None, "retrieval_min_subjects": 2, "chance_trials": 100, "ceiling_jitter_deg": 0.0,
                     "mesh_baselines": None, "baseline_max_vertices": None, "baseline_smacof_eps": 1e-4,
                     "baseline_landmarks": 300}

# a flat task key of the old layout -> (its node, its key there); None: the net's config
FLAT_TASK_KEYS = {
    "use_lfe": (None, "use_lfe"), "use_msfe": (None, "use_msfe"),
    "lr": ("optimizer", "lr"), "betas": ("optimizer", "betas"), "lr_schedule": ("optimizer", "schedule"),
    "use_phases": ("phases", "use"), "phase_unit": ("phases", "unit"), "phases": ("phases", "weights"),
    "alpha": ("phases", "alpha"), "beta": ("phases", "beta"),
    "image_every_n_epochs": ("panels", "every_n_epochs"), "n_panel": ("panels", "n"),
    "identity_weight": ("identity", "weight"), "identity_classes": ("identity", "classes"),
    "phenotype_weight": ("phenotype", "weight"), "phenotype_dims": ("phenotype", "dims"),
    **{k: ("warp", k) for k in ("flow_weight", "flow_on", "flow_power", "vis_weight", "vis_on", "smooth_weight",
                                "offset_smooth_weight", "depth_grad_weight")},
    "contrastive_on": ("contrastive", "embed"),
    **{f"contrastive_{k}": ("contrastive", k) for k in ("weight", "temperature", "dim", "channels")},
}


# a parked option of the task config (today's node layout) -> the value at which it was off (studies/canonical/LOG.md);
# the data's: datamodules.canonical.parked.PARKED_DATA, dropped with the data config's upgrade
PARKED = {
    "net.head.normalise_depth": False, "net.head.depth": "affine", "net.head.parts": 0, "net.head.attend_grid": 0,
    "net.head.refine_steps": 1, "net.head.affine_cell": 8,
    "warp.flow_power": 1.0, "warp.flow_on": "visible", "warp.vis_on": "foreground", "warp.offset_smooth_weight": 0.0,
    "warp.depth_grad_weight": 0.0,
    "phenotype.weight": 0.0, "phenotype.dims": ANY,
    **{f"contrastive.{k}": ANY for k in ("embed", "temperature", "dim", "channels")}, "contrastive.weight": 0.0,
}
PARKED_VALUES = {"net.head.kind": ("splat",)}  # parked values of a kept key
# a warp head's output conv of the per-pixel depth offset (net.head.depth=offset, the default before the key
# existed): flow 2 + offset 1 + visibility and fills 3 channels
OFFSET_HEAD = ("net.head.out.weight", 6)


def is_canonical(ckpt: Mapping) -> bool:
    """Whether a checkpoint dict holds the canonical task (by its lit3d metadata)."""
    task = (ckpt.get(META_KEY) or {}).get("task") or {}
    return task.get("name") == "canonical" or task.get("_target_") == TASK_TARGET

# a flat key of the old net config -> (its node, its key there) (lit3d.canonical.net_settings)
FLAT_NET_KEYS = {
    "use_lfe": ("lfe", "use"), "lfe_channels": ("lfe", "channels"), "lfe_out": ("lfe", "out"),
    "use_msfe": ("msfe", "use"), "msfe_channels": ("msfe", "channels"), "msfe_grid": ("msfe", "grid"),
    "fuser_hidden": ("msfe", "fuser_hidden"), "fuser_out": ("msfe", "fuser_out"),
    "msfe_dec_channels": ("msfe", "dec_channels"), "msfe_out": ("msfe", "out"),
    "reconstruction": ("reconstruction", "kind"), "rec_channels": ("reconstruction", "channels"),
    "head": ("head", "kind"), "warp_hidden": ("head", "hidden"), "warp_normalise_depth": ("head", "normalise_depth"),
    "warp_depth": ("head", "depth"), "warp_affine_cell": ("head", "affine_cell"), "warp_parts": ("head", "parts"),
    "warp_refine_steps": ("head", "refine_steps"), "warp_attend_grid": ("head", "attend_grid"),
}


def upgrade_net(net: Mapping) -> dict:
    """A net config of the flat layout (``lfe_channels``, ``head: warp``, ``warp_hidden``, ...) with its parts as
    nodes (``lfe``, ``msfe``, ``reconstruction``, ``head``); today's layout comes back unchanged."""
    out: dict = {}
    for key, value in net.items():
        if key in FLAT_NET_KEYS and not isinstance(value, Mapping):
            node, name = FLAT_NET_KEYS[key]
            out.setdefault(node, {})[name] = value
        else:
            out[key] = value
    return out


def upgrade_hparams(hparams: Mapping, keep_evaluation: bool = False, source: str | None = None) -> dict:
    """The task's hyper-parameters (or task config) of a checkpoint in today's layout: the flat keys of
    :data:`FLAT_TASK_KEYS` moved into their nodes, ``use_lfe``/``use_msfe`` into ``net``, the net's parts
    into theirs (:func:`upgrade_net`); the evaluation
    settings of :data:`EVALUATION_LEGACY` dropped (``keep_evaluation``: kept, for the task config). Today's
    layout comes back unchanged. The parked options of :data:`PARKED` are dropped at their defaults
    (:func:`~datamodules.canonical.parked.drop_parked`: :class:`~datamodules.canonical.parked.ParkedOptionError`
    naming ``source`` and the key for one at another value).
    ValueError for ``unet_baseline=true`` (removed: the plain U-Net is a run of its
    own, ``task.arch=unet``)."""
    out: dict = {}
    moved: dict[str, dict] = {}
    for key, value in hparams.items():
        if key == "unet_baseline":
            if value:
                raise ValueError("unet_baseline was removed: train the plain U-Net as a run of its own "
                                 "(task.arch=unet) and merge its rows with python -m studies.canonical.report RUN_DIR "
                                 "--unet UNET_RUN_DIR")
        elif key in EVALUATION_LEGACY:
            if keep_evaluation:
                out[key] = value
        elif key in FLAT_TASK_KEYS and not (key == "phases" and isinstance(value, Mapping)):
            node, name = FLAT_TASK_KEYS[key]
            moved.setdefault(node, {})[name] = value
        else:
            out[key] = value
    if None in moved or isinstance(out.get("net"), Mapping):
        out["net"] = upgrade_net({**dict(out.get("net") or {}), **moved.pop(None, {})})
    for node, values in moved.items():
        out[node] = {**dict(out.get(node) or {}), **values}
    return drop_parked(out, PARKED, "task.", source, PARKED_VALUES)


def upgrade_checkpoint(ckpt: dict, source: str | None = None) -> dict:
    """``ckpt`` (a loaded checkpoint dict) with its hyper-parameters, task config and data config in
    today's layout, when it is a canonical checkpoint; in place, returned. Parked options at their defaults
    are dropped; :class:`~datamodules.canonical.parked.ParkedOptionError` (a ValueError naming ``source``, the
    file, and the key) for one that the checkpoint used, and for a warp head with the per-pixel depth offset (its state dict's
    :data:`OFFSET_HEAD`, from before ``net.head.depth`` existed)."""
    if not isinstance(ckpt, dict) or not is_canonical(ckpt):
        return ckpt
    if "hyper_parameters" in ckpt:
        ckpt["hyper_parameters"] = upgrade_hparams(ckpt["hyper_parameters"], source=source)
    meta = ckpt[META_KEY]
    if isinstance(meta.get("task"), Mapping):
        keep = {k: v for k, v in meta["task"].items() if k in ("_target_", "name", "monitor", "monitor_mode")}
        task = upgrade_hparams({k: v for k, v in meta["task"].items() if k not in keep}, True, source)
        meta["task"] = {**task, **keep}
    if isinstance(meta.get("data"), Mapping):
        meta["data"] = upgrade_data_config(meta["data"], source)
    out = (ckpt.get("state_dict") or {}).get(OFFSET_HEAD[0])
    if out is not None and out.shape[0] == OFFSET_HEAD[1]:
        raise refuse(source, "task.net.head.depth", "offset")
    return ckpt
