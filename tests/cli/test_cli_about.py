"""Each command's --help says what it does with examples (Hydra's hydra/help template), and every
command has --version."""
from __future__ import annotations

import importlib
import re
import subprocess
import sys
from importlib import metadata
from pathlib import Path

import pytest
from hydra.core.global_hydra import GlobalHydra

from lit3d.cli.about import COMMANDS, lit3d_version
from lit3d.runtime.compose import CONF_DIR
from tests.helpers.paths import REPO

HYDRA_CLIS = {command: module for module, (command, _) in COMMANDS.items()}
ALL_GROUPS = sorted(p.name for p in Path(CONF_DIR).iterdir() if p.is_dir() and p.name != "hydra")


def _run_main(module: str, argv: list[str], monkeypatch, capsys) -> str:
    """``lit3d.cli.<module>.main()`` with ``argv``; returns stdout (it must exit 0 or return)."""
    monkeypatch.setattr(sys, "argv", [module, *argv])
    GlobalHydra.instance().clear()
    try:
        importlib.import_module(f"lit3d.cli.{module}").main()
    except SystemExit as exc:
        assert exc.code in (0, None), exc.code
    finally:
        GlobalHydra.instance().clear()
    return capsys.readouterr().out


@pytest.mark.parametrize("command", sorted(HYDRA_CLIS))
def test_help_opens_with_what_the_command_does_and_examples(command, monkeypatch, capsys):
    text = _run_main(HYDRA_CLIS[command], ["--help"], monkeypatch, capsys)
    lines = text.splitlines()
    assert lines[0].startswith(f"{command}: ") and "powered by Hydra" not in text
    examples = lines[lines.index("Examples:") + 1:]
    examples = examples[:next(i for i, ln in enumerate(examples) if not ln.strip())]
    assert len(examples) == 3 and all(ln.strip().startswith(command) for ln in examples), examples
    assert lines.index("Examples:") < 12  # the examples come first, before the groups and keys
    assert "== Config groups" in text and "== Main keys" in text and "--version" in text
    assert len(lines) < 70  # not the whole composed config


def test_eval_help_lists_only_the_groups_eval_uses(monkeypatch, capsys):
    text = _run_main("evaluate", ["--help"], monkeypatch, capsys)
    groups = text.split("== Config groups")[1].split("== Main keys")[0]
    named = set(re.findall(r"^\s+(\w+):", groups, re.M))
    assert named == {"task", "data", "trainer"}
    for unusable in ("logger", "callbacks", "experiment", "hparams_search", "debug", "sweep"):
        assert f"{unusable}:" not in text and f"{unusable}=" not in text, unusable


def test_data_help_mentions_show_and_names_real_options(monkeypatch, capsys):
    text = _run_main("data", ["--help"], monkeypatch, capsys)
    assert "--show N" in text and "lit3d-data task=completion --show 8" in text
    data_options = {p.stem for p in (Path(CONF_DIR) / "data").glob("*.yaml")}
    for page in ("data", "evaluate"):
        body = (Path(CONF_DIR) / "hydra" / "help" / f"{page}.yaml").read_text()
        for name in re.findall(r"e\.g\. ([\w, ]+)", body)[0].split(", "):
            assert name.strip() in data_options, (page, name)


def test_train_help_lists_every_config_group(monkeypatch, capsys):
    text = _run_main("train", ["--help"], monkeypatch, capsys)
    for group in ALL_GROUPS:
        assert f"\n{group}: " in text, group
    assert "hparams_search: canonical_optuna, completion_optuna" in text
    assert "callbacks: default, early_stopping, none" in text


@pytest.mark.parametrize("command", sorted(HYDRA_CLIS))
def test_hydra_cli_version(command, monkeypatch, capsys):
    assert _run_main(HYDRA_CLIS[command], ["--version"], monkeypatch, capsys) == f"{command} (lit3d) {lit3d_version()}\n"


@pytest.mark.parametrize("module, command", [("score", "lit3d-score"), ("reconstruct", "lit3d-reconstruct")])
def test_argparse_cli_version(module, command, capsys):
    with pytest.raises(SystemExit) as exc:
        importlib.import_module(f"lit3d.cli.{module}").main(["--version"])
    assert exc.value.code == 0 and capsys.readouterr().out == f"{command} (lit3d) {lit3d_version()}\n"


def test_version_is_the_installed_one():
    assert lit3d_version() == metadata.version("lit3d")


def test_console_script_help_and_version():
    exe = str(Path(sys.executable).parent / "lit3d-train")
    res = subprocess.run([exe, "--help"], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert res.returncode == 0 and res.stdout.startswith("lit3d-train: fit a task"), res.stderr[-2000:]
    assert "lit3d-train experiment=completion_demo" in res.stdout
    res = subprocess.run([exe, "--version"], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert res.returncode == 0 and res.stdout.strip() == f"lit3d-train (lit3d) {lit3d_version()}"


ARGPARSE_CLIS = ("score", "reconstruct", "eval_folder")
DOC_NAME = re.compile(r"(?<![\w/.])(README\.md|CHANGELOG\.md|CITATION\.cff|docs/[\w./-]*)")


def _project_url() -> str:
    import tomllib

    return tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["urls"]["Source"]


@pytest.mark.parametrize("command", sorted(HYDRA_CLIS) + [f"lit3d-{m.replace('_', '-')}" for m in ARGPARSE_CLIS])
def test_help_names_docs_by_their_online_address(command, monkeypatch, capsys):
    """A wheel ships no README.md or docs/: each command's --help names them by the project's address
    (``[project.urls]`` Source), and the page it names is in the checkout."""
    if command in HYDRA_CLIS:
        text = _run_main(HYDRA_CLIS[command], ["--help"], monkeypatch, capsys)
    else:
        module = command.removeprefix("lit3d-").replace("-", "_")
        text = importlib.import_module(f"lit3d.cli.{module}")._parser().format_help()
    url = _project_url()
    text = " ".join(text.split())
    for page in re.findall(re.escape(url) + r"/blob/main/([\w./-]*\w)", text):
        assert (REPO / page).is_file(), page
    local = DOC_NAME.findall(re.sub(re.escape(url) + r"[\w./-]*", "", text))
    assert not local, f"{command} --help names files a wheel does not ship: {local}"
