"""The optional hooks a task's LightningModule may define, declared once as :class:`typing.Protocol`\\ s.

The runtime and the callbacks ask ``isinstance(task, Protocol)`` instead of probing for names, so each hook
a task can offer is written down here with its meaning (``tests/utils/test_task_hooks.py`` checks which task
offers which):

- :class:`AdaptsDataConfig`: ``adapt_data_config(data_cfg) -> data_cfg``, the data config that
  ``lit3d-eval`` builds for this checkpoint (completion: its test splits' sizes and categories);
- :class:`ValidatesBeforeTest`: ``validate_before_test = True``: ``lit3d-eval`` runs the validation
  split first (completion: the decision threshold is chosen on validation);
- :class:`HasEvaluationLegacy`: ``evaluation_legacy``, ``{old hyper-parameter: evaluation.KEY}``, read for
  checkpoints saved before the ``evaluation`` node;
- :class:`HasHealthGroups`: ``health_groups() -> {name: [parameters]}``, the parameter groups whose
  gradient norms the health callback logs (default: the module's children).
"""
from __future__ import annotations

from typing import Any, Protocol, runtime_checkable


@runtime_checkable
class AdaptsDataConfig(Protocol):
    def adapt_data_config(self, data_cfg: dict) -> dict: ...


@runtime_checkable
class ValidatesBeforeTest(Protocol):
    validate_before_test: bool


@runtime_checkable
class HasEvaluationLegacy(Protocol):
    evaluation_legacy: dict[str, str]


@runtime_checkable
class HasHealthGroups(Protocol):
    def health_groups(self) -> dict[str, list[Any]]: ...


def validates_before_test(task: object) -> bool:
    """Whether ``lit3d-eval`` runs ``task``'s validation split before its test splits."""
    return isinstance(task, ValidatesBeforeTest) and bool(task.validate_before_test)


def evaluation_legacy(task_cls: type) -> dict[str, str]:
    """``task_cls.evaluation_legacy`` (empty for a task without one)."""
    return dict(task_cls.evaluation_legacy or {}) if isinstance(task_cls, HasEvaluationLegacy) else {}
