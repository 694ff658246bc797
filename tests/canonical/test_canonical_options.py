"""Every setting of the canonical task's config is set by an experiment, sweep or search, and every setting of
its DataModule by those or a data config, or listed in the "Supported options" table of docs/results_canonical.md
(studies.canonical.unset_keys); a key that nobody sets and nobody documents fails here, and so does a table row for
a key the config or the DataModule no longer has. The DataModule's settings nodes are taken as mappings or as their
dataclasses."""
import shutil
from pathlib import Path

import pytest

from datamodules.canonical import CanonicalDataModule
from datamodules.canonical.settings import RenderSettings, TrainingSettings
from studies.canonical import unset_keys as uk


def test_every_unset_key_is_a_documented_option():
    keys, unset = uk.unset_keys()
    documented = uk.documented_keys()
    assert len(keys) > 40 and unset, "the counter found no keys: it reads nothing"
    assert [k for k in unset if k not in documented] == []
    data = {uk.dotted(k) for k in uk.data_keys()}
    assert [k for k in documented if k not in keys and k not in data] == [], "table rows for keys nothing has"


def test_every_unset_data_key_is_a_documented_option():
    keys, unset = uk.unset_data_keys()
    assert len(keys) > 40 and "data.render.flow_targets" in keys and "data.source.classes (tosca)" in keys
    assert "data.render.forward_flow" not in keys and "data.phenotype_targets" not in keys  # parked, removed
    documented = uk.documented_keys()
    assert [k for k in unset if uk.dotted(k) not in documented] == []


def _tree(tmp_path: Path) -> Path:
    """A copy of the files the counter reads, under ``tmp_path``."""
    files = [*uk.setting_files(), *uk.data_configs()]
    for rel in [str(uk.TASK_CONFIG), str(uk.OPTIONS_PAGE), *(str(p.relative_to(uk.ROOT)) for p in files)]:
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(uk.ROOT / rel, tmp_path / rel)
    return tmp_path


def test_a_new_key_that_no_experiment_sets_is_caught(tmp_path):
    root = _tree(tmp_path)
    config = root / uk.TASK_CONFIG
    config.write_text(config.read_text().replace("  init_weights: null\n", "  init_weights: null\n  new_knob: 3\n"))
    keys, unset = uk.unset_keys(root)
    assert "task.new_knob" in keys and "task.new_knob" in unset and "task.new_knob" not in uk.documented_keys(root)
    # set by a sweep's params, it is no longer unset
    sweep = root / "sweeps" / "canonical_new.yaml"
    sweep.write_text("hydra:\n  sweeper:\n    params:\n      task.new_knob: 1,2\n")
    assert "task.new_knob" not in uk.unset_keys(root)[1]


def test_a_data_key_that_no_config_sets_is_caught_until_the_table_lists_it(tmp_path):
    root = _tree(tmp_path)
    synth = root / "lit3d/conf/data/canonical_synth.yaml"
    text = synth.read_text()
    assert "\n  own_poses: 0" in text
    synth.write_text(text.replace("\n  own_poses: 0", "\n  # own_poses: 0"))
    experiment = root / "lit3d/conf/experiment/canonical_demo.yaml"
    experiment.write_text(experiment.read_text().replace("own_poses: 16", "# own_poses: 16"))
    unset = uk.unset_data_keys(root)[1]
    assert unset == ["data.source.own_poses (synth)"] and "data.source.own_poses" not in uk.documented_keys(root)
    page = root / uk.OPTIONS_PAGE
    row = "| `data.source.own_poses` | `0` | N more training-only poses of each figure |\n"
    page.write_text(page.read_text().replace("\n## Known limits", row + "\n## Known limits"))
    assert "data.source.own_poses" in uk.documented_keys(root)
    # a source field is set only by a data config of its own kind: tosca's up_axis, though shrec14 sets its own
    tosca = root / "lit3d/conf/data/tosca.yaml"
    tosca.write_text(tosca.read_text().replace("\n  up_axis: z", ""))
    assert "data.source.up_axis (tosca)" in uk.unset_data_keys(root)[1]
    assert "data.source.up_axis (shrec14)" not in uk.unset_data_keys(root)[1]


def test_a_node_set_whole_sets_its_leaves_and_interpolations_are_not_options(tmp_path):
    root = _tree(tmp_path)
    (root / "lit3d/conf/experiment/canonical_whole.yaml").write_text("task:\n  panels: {every_n_epochs: 0, n: 2}\n")
    keys, unset = uk.unset_keys(root)
    assert "task.panels.n" not in unset and "task.panels.every_n_epochs" not in unset
    assert "task.net.image_size" not in keys and "task._target_" not in keys


def test_bad_files_are_one_line_naming_the_file(tmp_path, capsys, monkeypatch):
    root = _tree(tmp_path)
    kindless = root / "lit3d/conf/data/views/kindless.yaml"
    kindless.write_text("source:\n  n_poses: 3\n")
    with pytest.raises(uk.ConfigFileError, match=r"data/views/kindless\.yaml: its source node has no kind$"):
        uk.unset_data_keys(root)
    kindless.unlink()
    (root / "sweeps" / "canonical_bad.yaml").write_text("hydra: [unclosed\n")
    with pytest.raises(uk.ConfigFileError, match=r"canonical_bad\.yaml: not readable as YAML"):
        uk.unset_keys(root)
    page = root / uk.OPTIONS_PAGE
    page.write_text(page.read_text().replace(uk.OPTIONS_HEADING, "## Options"))
    with pytest.raises(uk.ConfigFileError, match=r"results_canonical\.md: no '## Supported options' section"):
        uk.documented_keys(root)
    monkeypatch.setattr(uk, "ROOT", root)
    monkeypatch.setattr(uk.unset_keys, "__defaults__", (root,))
    assert uk.main([]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: sweeps/canonical_bad.yaml: not readable as YAML")


def test_settings_given_as_their_dataclasses_are_taken_as_they_are(tmp_path):
    """The nodes may come as their dataclasses (the constructor's types), not only as mappings: the check for
    removed keys reads the keys of a mapping only."""
    render, training = RenderSettings(azimuths=(0.0, 90.0), flow_targets=True), TrainingSettings(flip_lr=True)
    dm = CanonicalDataModule(str(tmp_path), image_size=32, render=render, training=training)
    assert dm.render is render and dm.training is training
