"""Every setting of the canonical task's config is set by an experiment, sweep or search, or listed in the
"Supported options" table of docs/results_canonical.md (studies.canonical.unset_keys); a key that nobody sets
and nobody documents fails here, and so does a table row for a key the config no longer has."""
import shutil
from pathlib import Path

import pytest

from studies.canonical import unset_keys as uk


def test_every_unset_key_is_a_documented_option():
    keys, unset = uk.unset_keys()
    documented = uk.documented_keys()
    assert len(keys) > 40 and unset, "the counter found no keys: it reads nothing"
    assert [k for k in unset if k not in documented] == []
    assert [k for k in documented if k not in keys] == [], "table rows for keys the task config does not have"


def _tree(tmp_path: Path) -> Path:
    """A copy of the files the counter reads, under ``tmp_path``."""
    for rel in [str(uk.TASK_CONFIG), str(uk.OPTIONS_PAGE), *(str(p.relative_to(uk.ROOT)) for p in uk.setting_files())]:
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


def test_a_node_set_whole_sets_its_leaves_and_interpolations_are_not_options(tmp_path):
    root = _tree(tmp_path)
    (root / "lit3d/conf/experiment/canonical_whole.yaml").write_text("task:\n  panels: {every_n_epochs: 0, n: 2}\n")
    keys, unset = uk.unset_keys(root)
    assert "task.panels.n" not in unset and "task.panels.every_n_epochs" not in unset
    assert "task.net.image_size" not in keys and "task._target_" not in keys


def test_bad_files_are_one_line_naming_the_file(tmp_path, capsys, monkeypatch):
    root = _tree(tmp_path)
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
