"""``lit3d-eval``: evaluate a checkpoint without training.

    lit3d-eval ckpt_path=logs/completion/runs/X/checkpoints/last.ckpt
    lit3d-eval task=completion ckpt_path=... data=recgan data.root=../shared/data/recgan_sample
    lit3d-eval task=canonical ckpt_path=... evaluation.mesh_baselines=[]    # other evaluation settings
    lit3d-eval ckpt_path=... split=val data.split.max_val_items=null         # the validation split's val/ metrics

Without ``data=NAME`` the checkpoint's own data config is used; ``data.KEY=VALUE`` overrides
(``data.num_workers=1``, ``data.sizes.test=4``) then change that config (:func:`data_overrides`):
each key must be one of the checkpoint's data config, and its value passes ``lit3d-train``'s checks.

Evaluates with the evaluation settings the checkpoint was trained with (saved by lit3d-train), except
those the command line sets (``evaluation.*``; with ``task=NAME``, whose config brings the node):
:mod:`lit3d.runtime.eval_settings`.

``split=val``: the validation split only, its ``val/`` metrics into metrics.json (with config.yaml, and for
the canonical task the validation items' predictions as heldout.npz, which ``lit3d-summary --pooled`` scores;
no results.md or figures): settings chosen on validation items, not on the test set
(:func:`lit3d.cli.evaluation.run_validation`).

Writes into the run dir: metrics.json, results.md (the thesis's table layout,
with the thesis's figures beside ours), config.yaml and PNG figures, as one set (staged, then moved
in with metrics.json last: :mod:`lit3d.cli.evaluation`). Validation runs first
when the task picks a threshold there (completion), then test. Ctrl-C or SIGTERM stops it with exit
143 and one line; nothing is written then (:mod:`lit3d.cli.stops`).
"""
from __future__ import annotations

import sys
from pathlib import Path

import hydra
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from lit3d.runtime import eval_settings
from lit3d.cli.about import EXIT_USER
from lit3d.cli.common import cli_main, fail, run_cli
from lit3d.utils.task_hooks import AdaptsDataConfig, validates_before_test
from lit3d.cli.evaluation import run_evaluation, run_validation
from lit3d.runtime.build import build_datamodule, import_object, to_plain
from lit3d.runtime.checkpoints import read_checkpoint
from lit3d.runtime.compose import CONF_DIR
from lit3d.runtime.errors import UserError
from lit3d.runtime.config_checks import ConfigValueError, check_config_values
from lit3d.cli.resume_checks import check_eval_data
from lit3d.cli.stops import evaluating
from lit3d.utils.provenance import provenance


SPLITS = ("test", "val")  # split=val: the validation split's val/ metrics only (run_validation)


def checkpoint_meta_for(cfg: DictConfig) -> tuple[dict, dict]:
    """The checkpoint and its lit3d metadata; refuses a checkpoint of another task than ``task=NAME``, and
    one of another task than the data config's (``data=NAME``, :func:`check_eval_data`)."""
    ckpt, meta = read_checkpoint(cfg.ckpt_path)
    have = (meta.get("task") or {}).get("name")
    wanted = cfg.get("task_info")
    if wanted is not None and wanted.get("name") != have:
        raise UserError(f"{cfg.ckpt_path}: checkpoint is for task '{have}', not '{wanted.get('name')}'")
    check_eval_data(cfg.ckpt_path, meta, cfg.get("data"))
    return ckpt, meta


def evaluate(cfg: DictConfig) -> dict[str, float]:
    """Test ``cfg.ckpt_path`` and write its outputs into the run dir as one set; Ctrl-C or SIGTERM
    stops it with one line and nothing written (:func:`lit3d.cli.stops.evaluating`)."""
    out_dir = Path(cfg.paths.output_dir)
    with evaluating(out_dir):
        return _evaluate(cfg, out_dir)


def _evaluate(cfg: DictConfig, out_dir: Path) -> dict[str, float]:
    if cfg.split not in SPLITS:
        raise UserError(f"split={cfg.split}: expected one of {', '.join(SPLITS)}")
    ckpt, meta = checkpoint_meta_for(cfg)  # before the heavy imports: a wrong checkpoint fails fast
    import lightning.pytorch as pl
    import torch

    from lit3d.callbacks.stop_points import StopPoints

    out_dir.mkdir(parents=True, exist_ok=True)
    pl.seed_everything(cfg.seed, workers=True)
    torch.set_float32_matmul_precision(cfg.matmul_precision)
    task_cfg = meta["task"]
    task_cls = import_object(task_cfg["_target_"])
    # the hyper-parameters as read (a canonical checkpoint's in today's layout: lit3d.canonical.checkpoint_upgrade)
    # over the file's; keys the constructor lacks are left out by Lightning
    task = task_cls.load_from_checkpoint(cfg.ckpt_path, map_location="cpu", weights_only=True,
                                         **(ckpt.get("hyper_parameters") or {}))
    settings = eval_settings.resolve(cfg, ckpt, meta, task_cls)  # the checkpoint's; the command line's win
    del ckpt
    data_cfg = to_plain(cfg.data) if cfg.get("data") is not None else dict(meta["data"])
    data_cfg = with_data_overrides(data_cfg, to_plain(cfg.get(DATA_OVERRIDES)), cfg.ckpt_path)
    if isinstance(task, AdaptsDataConfig):
        data_cfg = task.adapt_data_config(data_cfg)
    datamodule = build_datamodule(data_cfg)
    trainer: pl.Trainer = instantiate(cfg.trainer, logger=False, enable_checkpointing=False,
                                      callbacks=[pl.callbacks.RichProgressBar(), StopPoints()])

    def record() -> dict:  # after the test: this code and the data evaluated; the checkpoint's own provenance
        return {"ckpt_path": str(cfg.ckpt_path),
                "provenance": {**provenance(datamodule), "checkpoint": meta.get("provenance")}}

    config = OmegaConf.to_yaml(OmegaConf.create({"task": task_cfg, "data": data_cfg, "evaluation": settings}))
    if cfg.split == "val":
        return run_validation(trainer, task, datamodule, task_cfg["name"], out_dir, extra=record,
                              files={"config.yaml": config}, settings=settings)
    return run_evaluation(trainer, task, datamodule, task_cfg["name"], out_dir,
                          validate=validates_before_test(task), n_figures=cfg.n_figures,
                          extra=record, files={"config.yaml": config}, settings=settings)


DATA_OVERRIDES = "data_overrides"  # where data.KEY=VALUE goes without data=NAME (no data node to override)


def data_overrides(args: list[str]) -> list[str]:
    """The command line with ``data.KEY=VALUE`` (also ``+data.KEY`` / ``++data.KEY``) turned into
    ``+data_overrides.KEY=VALUE`` when no ``data=NAME`` is given: Hydra's config has no data node then,
    and refused them with its hint to add ``+data...``; :func:`with_data_overrides` applies them to the
    checkpoint's data config. Their values are checked here, before Hydra creates the run dir
    (:func:`lit3d.runtime.config_checks.check_config_values`)."""
    if any(a.split("=", 1)[0].lstrip("+~") == "data" for a in args if "=" in a):
        return args  # data=NAME: Hydra overrides its node itself
    out, moved = [], []
    for a in args:
        key, sep, value = a.partition("=")
        if sep and not a.startswith("-") and key.lstrip("+").startswith("data.") and not key.startswith("~"):
            moved.append(f"{key.lstrip('+')}={value}")
            out.append(f"+{DATA_OVERRIDES}.{key.lstrip('+')[len('data.'):]}={value}")
        else:
            out.append(a)
    if moved:
        try:
            check_config_values(OmegaConf.from_dotlist(moved))
        except ConfigValueError as exc:
            fail(exc, EXIT_USER)
        except Exception:  # a value only Hydra parses (a list, an interpolation): Hydra and the merge check it
            pass
    return out


def _dict_keys(node: dict, prefix: tuple = ()) -> list[tuple]:
    """The key paths of the leaves of nested dicts (a list value is one leaf)."""
    out = []
    for k, v in node.items():
        out += _dict_keys(v, (*prefix, str(k))) if isinstance(v, dict) and v else [(*prefix, str(k))]
    return out


def with_data_overrides(data_cfg: dict, overrides: dict, ckpt_path) -> dict:
    """``data_cfg`` (the checkpoint's) with ``overrides`` (:func:`data_overrides`) merged in; a key the
    checkpoint's data config does not have, or a value of the wrong type, is one :class:`UserError` line."""
    if not overrides:
        return data_cfg
    for parts in _dict_keys(overrides):
        node = data_cfg
        for i, part in enumerate(parts):
            if not isinstance(node, dict) or part not in node:
                known = ", ".join(sorted(node)) if isinstance(node, dict) else "(not a group)"
                raise UserError(f"data.{'.'.join(parts[:i + 1])}: not a key of the checkpoint's data config "
                                f"({ckpt_path}); known: {known}")
            node = node[part]
    merged = to_plain(OmegaConf.merge(OmegaConf.create(data_cfg), OmegaConf.create(overrides)))
    check_config_values(OmegaConf.create({"data": merged}))
    return merged


@hydra.main(version_base="1.3", config_path=CONF_DIR, config_name="eval")
def hydra_main(cfg: DictConfig) -> None:
    run_cli(evaluate, cfg)


def main() -> None:
    """Console script ``lit3d-eval`` (``--debug``: tracebacks instead of one-line errors)."""
    cli_main(hydra_main, data_overrides(sys.argv[1:]), config_name="eval")


if __name__ == "__main__":
    main()
