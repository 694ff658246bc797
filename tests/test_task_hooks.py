"""The optional task hooks are declared (lit3d.utils.task_hooks) and found by isinstance, not by name probes."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from lit3d.body.module import BodyRegressorTask
from lit3d.canonical.module import CanonicalTask
from lit3d.completion.module import CompletionTask
from lit3d.quality.module import QualityTask
from lit3d.utils.task_hooks import (AdaptsDataConfig, HasEvaluationLegacy, HasHealthGroups, ValidatesBeforeTest,
                                    evaluation_legacy, validates_before_test)

ROOT = Path(__file__).resolve().parents[1]
HOOKS = (AdaptsDataConfig, ValidatesBeforeTest, HasEvaluationLegacy, HasHealthGroups)


@pytest.mark.parametrize("task_cls, offers", [
    (CompletionTask, {AdaptsDataConfig, ValidatesBeforeTest, HasEvaluationLegacy, HasHealthGroups}),
    (QualityTask, {HasEvaluationLegacy}),
    (CanonicalTask, {HasEvaluationLegacy}),
    (BodyRegressorTask, set()),
])
def test_each_task_offers_its_hooks(task_cls, offers):
    assert {h for h in HOOKS if isinstance(task_cls, h)} == offers


def test_hook_readers_give_the_defaults_for_a_task_without_them():
    class Bare:
        pass

    assert not validates_before_test(Bare()) and evaluation_legacy(Bare) == {}
    assert validates_before_test(CompletionTask) and evaluation_legacy(CompletionTask)


def test_no_name_probe_for_a_declared_hook():
    names = "|".join(["adapt_data_config", "validate_before_test", "evaluation_legacy", "health_groups"])
    probe = re.compile(rf"""(hasattr|getattr)\([^)]*["']({names})["']""")
    found = [f"{p.relative_to(ROOT)}:{i}" for p in sorted((ROOT / "lit3d").rglob("*.py"))
             for i, line in enumerate(p.read_text().splitlines(), 1) if probe.search(line)]
    assert not found, f"use lit3d.utils.task_hooks instead of probing: {found}"
