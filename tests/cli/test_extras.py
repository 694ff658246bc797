"""A feature whose optional extra is not installed (``pip install lit3d`` without ``[body]``, ``[wandb]`` ...)
says so in one line naming the extra, exit 2, before anything is made (:mod:`lit3d.utils.extras`).

A missing module is simulated by ``sys.modules[name] = None``, which makes ``import name`` raise
ImportError and :func:`importlib.util.find_spec` find nothing, as in an install without it.
"""
from __future__ import annotations

import sys

import numpy as np
import pytest
from PIL import Image

from lit3d.cli.common import cli_main
from lit3d.runtime.compose import compose_config
from lit3d.runtime.extra_checks import NO_WANDB_NOTE, default_logger
from lit3d.utils.extras import EXTRAS, MissingExtra, has_extra, installed, require
from tests.helpers.paths import REPO


def _without(monkeypatch, *modules: str) -> None:
    for name in modules:
        monkeypatch.setitem(sys.modules, name, None)


def _never_run():
    raise AssertionError("the command went on to run: the missing extra was not caught before any work")


def _lines(capsys) -> list[str]:
    return [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]


def test_require_names_the_extra_and_is_an_import_error(monkeypatch):
    assert installed("json") and not installed("no_such_module_here") and not installed("no_such_pkg.sub")
    _without(monkeypatch, "anny")
    assert not has_extra("body")
    with pytest.raises(MissingExtra, match=r"^--body needs the Anny body model: pip install 'lit3d\[body\]'$"):
        require("body", "--body")
    with pytest.raises(ImportError):  # code that caught the failed import still does
        require("body", "--body")


def test_every_extra_is_one_of_pyproject():
    import tomllib

    extras = tomllib.loads((REPO / "pyproject.toml").read_text())["project"][
        "optional-dependencies"]
    assert set(EXTRAS) <= set(extras)
    assert extras["all"] == [f"lit3d[{','.join(EXTRAS)}]"], "lit3d[all]: every extra of lit3d.utils.extras"


def test_reconstruct_body_without_anny_is_one_line(tmp_path, capsys, monkeypatch):
    from lit3d.cli.reconstruct import main

    _without(monkeypatch, "anny")
    depth = np.zeros((48, 64), np.uint16)
    depth[10:40, 20:44] = 2000
    Image.fromarray(depth).save(tmp_path / "person.png")
    out = tmp_path / "out"
    assert main([str(tmp_path / "person.png"), "--body", "--out", str(out)]) == 2
    assert _lines(capsys) == ["lit3d-reconstruct: error: --body needs the Anny body model: pip install 'lit3d[body]'"]
    assert not out.exists()


# (command line, the module that is missing, the one line)
HYDRA_CASES = [
    (["experiment=canonical_humans"], "anny",
     "error: experiment=canonical_humans (data.source.kind=anny) needs the Anny body model: pip install 'lit3d[body]'"),
    (["experiment=canonical_demo", "data=anny"], "anny",
     "error: data.source.kind=anny needs the Anny body model: pip install 'lit3d[body]'"),
    (["experiment=completion_demo", "logger=wandb"], "wandb",
     "error: logger=wandb needs Weights & Biases (wandb): pip install 'lit3d[wandb]'"),
    (["experiment=completion_demo", "logger=[csv,tensorboard]"], "tensorboard",
     "error: logger=tensorboard needs TensorBoard: pip install 'lit3d[tensorboard]'"),
    (["-m", "experiment=completion_demo", "hydra/launcher=slurm_local"], "hydra_plugins.hydra_submitit_launcher",
     "error: hydra/launcher=slurm_local needs Hydra's submitit launcher: pip install 'lit3d[slurm]'"),
    (["hparams_search=completion_optuna", "experiment=completion_demo"], "hydra_plugins.hydra_optuna_sweeper",
     "error: hparams_search=completion_optuna needs Hydra's Optuna sweeper: pip install 'lit3d[optuna]'"),
]


@pytest.mark.parametrize("args,missing,line", HYDRA_CASES, ids=[c[1] + ":" + c[0][-1] for c in HYDRA_CASES])
def test_hydra_command_without_its_extra_is_one_line(args, missing, line, tmp_path, capsys, monkeypatch):
    """What ``lit3d-train`` runs (:func:`cli_main`): exit 2, the one line, and no run dir."""
    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)
    _without(monkeypatch, missing)
    run_dir = tmp_path / "run"
    with pytest.raises(SystemExit) as info:
        cli_main(_never_run, [*args, f"hydra.run.dir={run_dir}", f"hydra.sweep.dir={run_dir}"])
    assert info.value.code == 2 and _lines(capsys) == [line]
    assert not run_dir.exists()


def test_lit3d_data_with_anny_data_needs_body_too(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)
    _without(monkeypatch, "anny")
    with pytest.raises(SystemExit) as info:
        cli_main(_never_run, ["experiment=canonical_people", f"hydra.run.dir={tmp_path}/run"], command="data")
    assert info.value.code == 2 and _lines(capsys)[-1].endswith("pip install 'lit3d[body]'")


def test_the_data_module_and_the_body_fit_check_too(tmp_path, monkeypatch):
    """Paths that do not start at a command line (lit3d-eval on a checkpoint's own data config, the Python
    API): the DataModule of the Anny data, the body fit and the body regressor."""
    from datamodules.canonical import CanonicalDataModule
    from lit3d.body_fit.model import Body
    from lit3d.body_fit.regressor import load_regressor
    from lit3d.zoo import ZOO

    _without(monkeypatch, "anny")
    with pytest.raises(MissingExtra, match=r"data.source.kind=anny needs .*lit3d\[body\]"):
        CanonicalDataModule(str(tmp_path), 64, source={"kind": "anny"})
    with pytest.raises(MissingExtra, match=r"lit3d\[body\]"):
        Body()
    with pytest.raises(MissingExtra, match=r"the body regressor needs .*lit3d\[body\]"):
        load_regressor(ZOO["body-regressor"].path)
    CanonicalDataModule(str(tmp_path), 64, source={"kind": "synth"})  # the procedural figures need no extra


def test_default_logger_is_none_without_wandb(capsys, monkeypatch):
    """lit3d-train's default logger (W&B) falls back to the CSV log alone, with a note, where wandb is
    missing; a logger on the command line is kept (and then checked)."""
    args = ["experiment=completion_demo"]
    composed = compose_config("train", args, return_hydra_config=True)
    assert composed.hydra.runtime.choices.logger == "wandb", "the default this fallback is for"
    assert default_logger(args, composed) == (args, None)  # wandb is installed here
    _without(monkeypatch, "wandb")
    assert default_logger(args, composed) == ([*args, "logger=none"], NO_WANDB_NOTE)
    assert default_logger([*args, "logger=wandb"], composed) == ([*args, "logger=wandb"], None)
    assert default_logger(["-m", *args], None) == (["-m", *args, "logger=none"], NO_WANDB_NOTE)
    assert default_logger(["--help", *args], None) == (["--help", *args], None)  # runs nothing: no note
    tb = compose_config("train", [*args, "logger=tensorboard"], return_hydra_config=True)
    assert default_logger(args, tb) == (args, None)  # a config whose logger is not the W&B default


def test_a_refused_command_line_without_wandb_is_still_one_line(tmp_path, capsys, monkeypatch):
    """No note about the logger before the error line (exit 2)."""
    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)
    _without(monkeypatch, "wandb", "anny")
    for args in (["experiment=canonical_humans"], ["experiment=completion_demo", "data.batch_size=0"]):
        with pytest.raises(SystemExit) as info:
            cli_main(_never_run, [*args, f"hydra.run.dir={tmp_path}/run"])
        lines = _lines(capsys)
        assert info.value.code == 2 and len(lines) == 1 and lines[0].startswith("error: "), lines


def test_train_without_wandb_composes_with_the_csv_log_only(tmp_path, capsys, monkeypatch):
    """Through :func:`cli_main`: the command line Hydra gets ends with ``logger=none``."""
    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)
    _without(monkeypatch, "wandb")
    monkeypatch.setattr(sys, "argv", ["lit3d-train"])  # cli_main hands Hydra its command line in sys.argv
    argv = cli_main(lambda: list(sys.argv[1:]), ["experiment=completion_demo", f"hydra.run.dir={tmp_path}/run"])
    assert argv[-1] == "logger=none"
    assert _lines(capsys) == [f"note: {NO_WANDB_NOTE}"]


def test_colour_measures_without_piq_name_the_install_line(monkeypatch, capsys):
    """piq is no extra (its torchvision would replace the CPU torch): its line says how to install it,
    and a command reports it as a user error (exit 2), not as an internal one."""
    from lit3d.cli.about import report_error
    from lit3d.metrics.image import colour_measures

    monkeypatch.setattr(colour_measures, "_PIQ_FUNCTIONS", {})  # nothing loaded yet
    _without(monkeypatch, "piq")
    with pytest.raises(MissingExtra, match=r"need piq: pip install --no-deps piq==0\.8\.0") as info:
        colour_measures.piq_functions()
    assert report_error("lit3d-score", info.value) == 2
    assert _lines(capsys) == [f"lit3d-score: error: {info.value}"]
