"""Types and ranges of config values, checked in one place before any work.

``lit3d-train``, ``lit3d-eval``, ``lit3d-data`` and ``lit3d-summary`` run :func:`check_config_values`
on the composed config (:func:`lit3d.cli.common.cli_main`, before Hydra creates the run dir, and
:func:`lit3d.cli.common.run_cli` again for every job of a multirun). A value of the wrong type or
out of range stops with exit 2 and one line naming the key, the value and what is expected::

    error: task.optimizer.lr_g=abc: expected a number > 0
    error: trainer.max_epochs=1.5: expected an integer >= 0, or -1 (no limit), or null

:data:`RULES` is the table: ``(key pattern, type, range)``. Patterns are ``fnmatch`` globs over
dotted keys (list items as ``key.0``, ``key.1`` ...); the first rule that matches a key decides,
and keys no rule matches are left to the constructors (which answer with ``task config: ...``).
Types: ``int`` (``count``: an int said as "a whole number of items"), ``number`` (int or float,
finite), ``bool``, ``str``, or two joined by ``|`` (the range is that of the number); a trailing
``?`` also allows ``null``. Ranges: ``>= a``, ``> a``, ``<= b``, ``< b``, intervals ``[a, b]``,
``[a, b)``, ``(a, b]``, ``(a, b)``, ``== a``; ``A or B`` allows either.
"""
from __future__ import annotations

import math
import operator
import os
import re
from fnmatch import fnmatchcase
from typing import Any, NamedTuple

from omegaconf import DictConfig, ListConfig, OmegaConf

from lit3d.utils.errors import Lit3dError


class Rule(NamedTuple):
    pattern: str
    kind: str                 # int | count | number | bool | str, or two joined by "|"; "?": null allowed too
    range: str = ""           # see the module doc; "" = any value of the type
    note: str = ""            # said after the range in the message, e.g. "(no limit)"


# fmt: off
RULES: tuple[Rule, ...] = (
    # run
    Rule("seed",                               "int",     ">= 0"),
    Rule("n_figures",                          "int",     ">= 0"),
    Rule("test_after_fit",                     "bool"),
    Rule("wait_for_run_dir",                   "bool"),
    Rule("show",                               "int",     ">= 0"),
    Rule("resume.allow_changes",               "bool"),
    # trainer (Lightning's own arguments)
    Rule("trainer.max_epochs",                 "int?",    ">= 0 or == -1", "(no limit)"),
    Rule("trainer.min_epochs",                 "int?",    ">= 0"),
    Rule("trainer.max_steps",                  "int?",    ">= 0 or == -1", "(no limit)"),
    Rule("trainer.min_steps",                  "int?",    ">= 0"),
    Rule("trainer.check_val_every_n_epoch",    "int?",    ">= 1"),
    Rule("trainer.log_every_n_steps",          "int?",    ">= 1"),
    Rule("trainer.num_sanity_val_steps",       "int?",    ">= 0 or == -1", "(all)"),
    Rule("trainer.accumulate_grad_batches",    "int",     ">= 1"),
    Rule("trainer.limit_*_batches",            "number?", ">= 0"),
    Rule("trainer.val_check_interval",         "number?", "> 0"),
    Rule("trainer.gradient_clip_val",          "number?", ">= 0"),
    Rule("trainer.num_nodes",                  "int",     ">= 1"),
    Rule("trainer.deterministic",              "bool"),
    Rule("trainer.fast_dev_run",               "bool|int", ">= 0"),
    # data (every DataModule)
    Rule("data.batch_size",                    "int",     ">= 1"),
    Rule("data.num_workers",                   "int",     ">= 0"),
    Rule("data.prepare_workers",               "int",     ">= 0"),
    Rule("data.prepare.workers",               "int",     ">= 0"),
    Rule("data.feature_tables.workers",              "int",     ">= 0"),
    Rule("data.sizes.*",                       "count",   ">= 0"),
    Rule("data.seed",                          "int",     ">= 0"),
    Rule("data.source.pose_seed",              "int",     ">= 0"),
    Rule("data.image_size",                    "int",     ">= 8"),
    Rule("data.target_res",                    "int",     ">= 1"),
    Rule("data.input_factor",                  "int",     ">= 1"),
    Rule("data.render.render_factor",          "int",     ">= 1"),
    Rule("data.render.views_per_shape",        "int",     ">= 1"),
    Rule("data.source.mesh_resolution",        "int",     ">= 1"),
    Rule("data.source.n_subjects",             "int",     ">= 1"),
    Rule("data.source.n_poses",                "int",     ">= 1"),
    Rule("data.source.own_poses",              "int",     ">= 0"),
    Rule("data.split.n_folds",                 "int",     ">= 1"),
    Rule("data.split.fold",                    "int",     ">= 0"),
    Rule("data.split.max_val_items",           "int?",    ">= 0"),
    Rule("data.meshes.model_split.*",          "number",  "[0, 1]"),
    Rule("data.split.train_pose_fraction",     "number",  "(0, 1]"),
    Rule("data.source.pose_strength",          "number",  ">= 0"),
    Rule("data.source.yaw_range",              "number",  ">= 0"),
    Rule("data.training.roll_deg",             "number",  ">= 0"),
    Rule("data.render.azimuths.*",             "number"),
    Rule("data.skip_bad",                      "bool"),
    Rule("data.prepare.skip_bad",              "bool"),
    Rule("data.pin_memory",                    "bool"),
    Rule("data.prepare.compress",              "bool"),
    Rule("data.prepare.progress",              "bool"),
    Rule("data.training.flip_lr",              "bool"),
    Rule("data.render.flow_targets",           "bool"),
    Rule("data.training.balance_subjects",     "bool"),
    # task: optimisers and losses
    Rule("task.lr",                            "number",  "> 0"),
    Rule("task.adversarial.gp_precision",      "str"),
    Rule("task.optimizer.schedule",            "str"),
    Rule("task.optimizer.lr",                  "number",  "> 0"),
    Rule("task.optimizer.betas.*",             "number",  "[0, 1)"),
    Rule("task.lr_*",                          "number",  "> 0"),
    Rule("task.optimizer.lr_*",                "number",  "> 0"),
    Rule("task.optimizer.eps",                 "number",  "> 0"),
    Rule("task.momentum",                      "number",  "[0, 1]"),
    Rule("task.weight_decay",                  "number",  ">= 0"),
    Rule("task.loss.alpha",                    "number",  ">= 0"),
    Rule("task.loss.gamma",                    "number",  "[0, 1]"),
    Rule("task.loss.zeta",                     "number",  ">= 0"),
    Rule("task.adversarial.gp_lambda",         "number",  ">= 0"),
    Rule("task.loss.stage_weight",             "number",  ">= 0"),
    Rule("task.*_weight",                      "number",  ">= 0"),
    Rule("task.mask_threshold",                "number",  "[0, 1]"),
    Rule("task.phases.alpha",                  "number",  ">= 0"),
    Rule("task.phases.beta",                   "number",  ">= 0"),
    Rule("task.phases.use",                    "bool"),
    Rule("task.*.weight",                      "number",  ">= 0"),
    Rule("task.warp.*_weight",                 "number",  ">= 0"),
    Rule("task.adversarial.critic_steps",      "int",     ">= 1"),
    Rule("task.adversarial.gp_every",          "int",     ">= 1"),
    Rule("task.adversarial.start_epoch",       "int",     ">= 0"),
    Rule("task.prior_samples",                 "int",     ">= 1"),
    Rule("task.panels.image_every_n_epochs",   "int",     ">= 0"),
    Rule("task.panels.every_n_epochs",         "int",     ">= 0"),
    Rule("task.panels.mesh_every_n_epochs",    "int",     ">= 0"),
    Rule("task.identity.classes",              "int",     ">= 0"),
    Rule("task.panels.n",                      "int",     ">= 0"),
    Rule("task.seed",                          "int",     ">= 0"),
    Rule("task.adversarial.use",               "bool"),
    Rule("task.adversarial.critic_concat",     "bool"),
    Rule("task.compile_step",                  "bool"),
    Rule("task.use_*",                         "bool"),
    Rule("task.net.*.use",                     "bool"),
    # task: net sizes (completion: task.nets, canonical and quality: task.net)
    Rule("task.nets.*_channels.*",             "int",     ">= 1"),
    Rule("task.nets.*_res",                    "int",     ">= 1"),
    Rule("task.nets.*_dim",                    "int",     ">= 1"),
    Rule("task.nets.k",                        "int",     ">= 1"),
    Rule("task.nets.stages",                   "int",     "[1, 3]"),
    Rule("task.nets.n_classes",                "int",     ">= 1"),
    Rule("task.nets.selector",                 "bool"),
    Rule("task.nets.selector_norm",            "bool"),
    Rule("task.nets.global_skips",             "bool"),
    Rule("task.nets.input_skip",               "bool"),
    Rule("task.nets.classifier",               "bool"),
    Rule("task.nets.critic_sigmoid",           "bool"),
    Rule("task.net.*_channels.*",              "int",     ">= 1"),
    Rule("task.net.*.channels.*",              "int",     ">= 1"),
    Rule("task.net.*.out",                     "int",     ">= 1"),
    Rule("task.net.image_size",                "int?",    ">= 8"),  # null: no data in the config (lit3d-eval task=NAME)
    Rule("task.net.dropout",                   "number",  "[0, 1)"),
    Rule("task.net.batch_norm",                "bool"),
    Rule("task.net.*_out",                     "int",     ">= 1"),
    Rule("task.net.msfe.fuser_hidden",         "int",     ">= 1"),
    Rule("task.net.msfe.grid",                 "int",     ">= 1"),
    Rule("task.net.head.hidden",               "int",     ">= 1"),
    Rule("task.net.hidden",                    "int",     ">= 1"),
    Rule("task.net.blocks",                    "int",     ">= 1"),
    # the body task's data and net (datamodules.body, lit3d.body)
    Rule("data.draw",                          "count",   ">= 1"),
    Rule("data.reuse",                         "number",  "> 0"),
    Rule("data.buffer",                        "count",   ">= 1"),
    Rule("data.val_people",                    "count",   ">= 1"),
    Rule("data.test_people",                   "count",   ">= 0"),
    Rule("data.placement.lateral",             "number",  ">= 0"),
    Rule("task.net.width",                     "int",     ">= 1"),
    Rule("task.preprocess.size",               "int",     ">= 8"),
    Rule("task.preprocess.depth_unit",         "number",  "> 0"),
    Rule("task.w_translation",                 "number",  ">= 0"),
    Rule("evaluation.anny_people",             "count",   ">= 0"),
    Rule("evaluation.refine_*",                "int",     ">= 0"),
    # evaluation settings (the evaluator's, not the module's: lit3d.runtime.eval_settings)
    Rule("evaluation.cv",                      "bool"),
    Rule("evaluation.chance_trials",           "int",     ">= 1"),
    Rule("evaluation.retrieval_min_subjects",  "int",     ">= 1"),
    Rule("evaluation.cv_epochs",               "int?",    ">= 1"),
    Rule("evaluation.surface.points",          "int",     ">= 1"),
)
# fmt: on

_TYPE_WORDS = {"int": "an integer", "count": "a whole number of items", "number": "a number", "bool": "true or false",
               "str": "a string"}
_OPS = {">=": operator.ge, ">": operator.gt, "<=": operator.le, "<": operator.lt, "==": operator.eq}
_BOUND = re.compile(r"^(>=|>|<=|<|==)\s*(-?[\d.]+(?:e-?\d+)?)$")
_INTERVAL = re.compile(r"^([\[(])\s*(-?[\d.]+)\s*,\s*(-?[\d.]+)\s*([\])])$")


class ConfigValueError(Lit3dError, ValueError):
    """A config value of the wrong type or out of range: ``<key>=<value>: expected <what>``."""


def _in_range(value: float, spec: str) -> bool:
    """``value`` within ``spec`` (the range grammar of the module doc)."""
    for part in (p.strip() for p in spec.split(" or ")):
        if m := _BOUND.match(part):
            if _OPS[m.group(1)](value, float(m.group(2))):
                return True
        elif m := _INTERVAL.match(part):
            lo, hi = float(m.group(2)), float(m.group(3))
            low_ok = value >= lo if m.group(1) == "[" else value > lo
            high_ok = value <= hi if m.group(4) == "]" else value < hi
            if low_ok and high_ok:
                return True
        else:
            raise ValueError(f"bad range {spec!r} in lit3d.runtime.config_checks.RULES")
    return False


def _type_ok(value: Any, kind: str) -> bool:
    if kind == "bool":
        return isinstance(value, bool)
    if kind == "str":
        return isinstance(value, str)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return False
    if kind in ("int", "count"):
        return isinstance(value, int)
    return math.isfinite(value)  # number


def expected(rule: Rule) -> str:
    """What ``rule`` asks for, in words: ``an integer >= 0, or -1 (no limit)``."""
    words = []
    for kind in rule.kind.rstrip("?").split("|"):
        text = _TYPE_WORDS[kind]
        if rule.range and kind in ("int", "count", "number"):
            text += " " + ", or ".join(p.strip().removeprefix("== ") for p in rule.range.split(" or "))
            text += f" {rule.note}" if rule.note else ""
        words.append(text)
    if rule.kind.endswith("?"):
        words.append("null")
    return ", or ".join(words)


def problem(rule: Rule, value: Any) -> str | None:
    """``None`` when ``value`` satisfies ``rule``, else what was expected."""
    if value is None and rule.kind.endswith("?"):
        return None
    for kind in rule.kind.rstrip("?").split("|"):
        if _type_ok(value, kind) and (not rule.range or kind in ("bool", "str") or _in_range(value, rule.range)):
            return None
    return expected(rule)


def show(value: Any) -> str:
    """A value as it is written on the command line (``true``, ``null``, ``abc``, ``1.5``)."""
    if isinstance(value, bool):
        return str(value).lower()
    if value is None:
        return "null"
    return str(value)


def rule_for(key: str, rules: tuple[Rule, ...] = RULES) -> Rule | None:
    """The first rule whose pattern matches the dotted ``key``."""
    return next((r for r in rules if fnmatchcase(key, r.pattern)), None)


def _leaves(node: Any, prefix: str = ""):
    """``(dotted key, value)`` of every leaf of a plain container; list items as ``key.0`` ..."""
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _leaves(v, f"{prefix}.{k}" if prefix else str(k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _leaves(v, f"{prefix}.{i}")
    else:
        yield prefix, node


def _plain_sections(cfg: DictConfig):
    """``(key, plain value)`` of every top-level entry but ``hydra``, interpolations resolved where
    they can be outside Hydra's runtime (else left out: Hydra resolves and checks those)."""
    for key in cfg.keys():
        if key == "hydra":
            continue
        node = cfg._get_node(key)  # OmegaConf's own node access: no resolution yet
        try:
            if isinstance(node, (DictConfig, ListConfig)):
                value = OmegaConf.to_container(node, resolve=True)
            else:
                value = cfg[key]
        except Exception:  # an interpolation only Hydra's runtime resolves: skip the unresolvable leaves
            value = OmegaConf.to_container(node, resolve=False) if isinstance(node, (DictConfig, ListConfig)) else None
            if isinstance(value, str) or value is None:
                continue
        yield str(key), value


def config_problems(cfg: DictConfig, rules: tuple[Rule, ...] = RULES) -> list[str]:
    """``<key>=<value>: expected <what>`` for every value of ``cfg`` that breaks its rule."""
    found = []
    no_data = cfg.get("data") is None  # lit3d-eval without data=: the checkpoint's data and sizes come later
    for section, value in _plain_sections(cfg):
        for key, leaf in _leaves(value, section):
            if isinstance(leaf, str) and "${" in leaf:
                continue  # unresolved interpolation (see _plain_sections)
            if no_data and section == "task" and leaf is None:
                continue  # a task size interpolated from the absent data node (task=NAME only names the task)
            rule = rule_for(key, rules)
            if rule is None:
                continue
            what = problem(rule, leaf)
            if what is not None:
                found.append(f"{key}={show(leaf)}: expected {what}")
    return found


def check_config_values(cfg: DictConfig | None) -> None:
    """Raise :class:`ConfigValueError` (one line, the first problem) when a value of ``cfg`` has the
    wrong type or is out of range (:data:`RULES`); ``None`` (nothing composed) passes."""
    if cfg is None:
        return
    found = config_problems(cfg)
    if found:
        more = f" (and {len(found) - 1} more)" if len(found) > 1 else ""
        raise ConfigValueError(found[0] + more)


# the folders of lit3d's own code, lit3d/ and datamodules/ side by side (in the checkout and in a wheel):
# errors raised there are its argument checks (config_problem)
_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.realpath(__file__))))
PROJECT_DIRS = tuple(os.path.join(_ROOT, name) + os.sep for name in ("lit3d", "datamodules"))
_SIGNATURE_ERRORS = ("unexpected keyword argument", "required positional argument", "required keyword-only argument",
                     "got multiple values for argument")


def _raised_by(exc: BaseException) -> str:
    """The file of the frame that raised ``exc`` (the innermost of its traceback; '' without one)."""
    tb, name = exc.__traceback__, ""
    while tb is not None:
        name, tb = tb.tb_frame.f_code.co_filename, tb.tb_next
    return name


def config_problem(exc: BaseException) -> bool:
    """True when ``exc``, raised while building a task or DataModule from its config, is the config's
    fault: a :class:`Lit3dError`, a ValueError raised by lit3d's own argument checks, or a TypeError of
    the call itself (an unknown or missing keyword). A ValueError or TypeError raised inside a library
    (torch, numpy...) or a TypeError inside lit3d's code is a bug, and keeps its traceback."""
    if isinstance(exc, Lit3dError):
        return True
    where = _raised_by(exc)
    ours = bool(where) and os.path.realpath(where).startswith(PROJECT_DIRS)
    if isinstance(exc, TypeError):
        return not ours and any(s in str(exc) for s in _SIGNATURE_ERRORS)
    return isinstance(exc, ValueError) and ours
