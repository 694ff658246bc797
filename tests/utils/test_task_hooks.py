"""The optional task hooks (lit3d.utils.task_hooks) and DataModule interfaces (lit3d.utils.data_hooks) are declared
and found by isinstance, not by name probes."""
from __future__ import annotations

import re

import pytest

from lit3d.body.module import BodyRegressorTask
from datamodules.body import BodyDataModule
from datamodules.canonical import CanonicalDataModule
from datamodules.completion import CompletionDataModule
from datamodules.quality import QualityDataModule
from lit3d.canonical.module import CanonicalTask
from lit3d.completion.module import CompletionTask
from lit3d.quality.module import QualityTask
from lit3d.utils.data_hooks import (GivesMeshes, HasEvaluationViews, HasLabelCategories, HasManifest, ListsHeldOut,
                                    NamesItsSource, RendersTurnedCanonical)
from lit3d.utils.task_hooks import (AdaptsDataConfig, HasEvaluationLegacy, HasHealthGroups, ValidatesBeforeTest,
                                    evaluation_legacy, validates_before_test)
from tests.helpers.paths import REPO as ROOT

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


# ----------------------------------------------------------------------------- DataModule interfaces
DATA_HOOKS = (HasManifest, HasLabelCategories, NamesItsSource, HasEvaluationViews, ListsHeldOut, RendersTurnedCanonical,
              GivesMeshes)


@pytest.mark.parametrize("make, offers", [
    (lambda: CompletionDataModule(data_dir="unused", target_res=32), {HasManifest, HasLabelCategories}),
    (lambda: QualityDataModule(data_dir="unused"), {HasManifest}),
    (lambda: CanonicalDataModule(data_dir="unused", image_size=32),
     {HasManifest, NamesItsSource, HasEvaluationViews, ListsHeldOut, RendersTurnedCanonical, GivesMeshes}),
    (lambda: BodyDataModule(), {HasManifest}),
], ids=["completion", "quality", "canonical", "body"])
def test_each_datamodule_offers_its_interfaces(make, offers):
    assert {h for h in DATA_HOOKS if isinstance(make(), h)} == offers


def test_no_name_probe_for_a_declared_data_interface():
    names = "|".join(["manifest", "label_categories", "user_categories", "source_kind", "views", "held_out_ids",
                      "canonical_turned", "normalized_mesh"])
    probe = re.compile(rf"""(hasattr|getattr)\([^)]*["']({names})["']""")
    found = [f"{p.relative_to(ROOT)}:{i}" for p in sorted((ROOT / "lit3d").rglob("*.py"))
             for i, line in enumerate(p.read_text().splitlines(), 1) if probe.search(line)]
    assert not found, f"use lit3d.utils.data_hooks instead of probing: {found}"
