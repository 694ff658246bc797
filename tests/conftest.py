"""Shared fixtures: Hydra config composition with per-test output dirs."""
from __future__ import annotations

import logging
import os
import signal
import subprocess
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from omegaconf import DictConfig, OmegaConf, open_dict

from lit3d.runtime.compose import CONF_DIR
from lit3d.utils import quiet

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / "shared" / "data"

os.environ.setdefault("WANDB_SILENT", "true")
os.environ.setdefault("WANDB_MODE", "offline")


def pytest_configure(config):
    """The entry points' filters for what lit3d cannot fix (lit3d.utils.quiet), in every test. A pytest-xdist
    worker starts with SIGINT ignored, and a child process inherits an ignored signal (Python then installs no
    Ctrl-C handler in it): the worker takes Python's own handler back, so the Ctrl-C tests' children get one."""
    if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    quiet.install()
    for line in quiet.pytest_filters():
        config.addinivalue_line("filterwarnings", line)


@pytest.fixture(scope="package")
def hydra_conf_dir() -> str:
    return CONF_DIR


@pytest.fixture
def compose_cfg(tmp_path):
    """compose_cfg(overrides, config_name="train") -> DictConfig with paths inside tmp_path.

    ``paths.output_dir`` (normally Hydra's run dir) and ``paths.data_dir`` point into the
    test's own tmp dir, so tests never share outputs.
    """

    def _compose(overrides: list[str] | None = None, config_name: str = "train", data_dir: Path | None = None) -> DictConfig:
        GlobalHydra.instance().clear()
        with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
            cfg = compose(config_name=config_name, overrides=list(overrides or []), return_hydra_config=False)
        with open_dict(cfg):
            cfg.paths.output_dir = str(tmp_path / "run")
            cfg.paths.data_dir = str(data_dir or tmp_path / "data")
            cfg.paths.log_dir = str(tmp_path / "logs")
        return cfg

    yield _compose
    GlobalHydra.instance().clear()


def _composed_task_nets(experiment: str) -> dict:
    """``task.nets`` of ``experiment=NAME`` as a plain dict (the config is the only source of sizes)."""
    GlobalHydra.instance().clear()
    try:
        with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
            cfg = compose(config_name="train", overrides=[f"experiment={experiment}"])
        return OmegaConf.to_container(cfg.task.nets, resolve=True)
    finally:
        GlobalHydra.instance().clear()


@pytest.fixture(scope="session")
def completion_demo_nets() -> dict:
    """The demo experiment's completion net sizes (16^3 -> 64^3); copy before changing it."""
    return _composed_task_nets("completion_demo")


@pytest.fixture(scope="session")
def completion_paper_nets() -> dict:
    """The thesis's completion net sizes (64^3 -> 256^3, conf/task/completion.yaml); copy before changing it."""
    return _composed_task_nets("completion_paper")


@pytest.fixture(scope="module")
def one_torch_thread():
    """Tiny nets: one intra-op thread is faster than two, and much faster on a shared CPU
    (``pytestmark = pytest.mark.usefixtures("one_torch_thread")`` in a module)."""
    import torch

    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


def pytest_collection_modifyitems(config, items):
    """GPU tests skip on machines without CUDA (they still run with -m gpu on a GPU box)."""
    try:
        import torch

        has_cuda = torch.cuda.is_available()
    except Exception:  # pragma: no cover
        has_cuda = False
    if has_cuda:
        return
    skip = pytest.mark.skip(reason="needs a CUDA GPU")
    for item in items:
        if item.get_closest_marker("gpu") is not None:
            item.add_marker(skip)




@pytest.fixture(autouse=True)
def _signals_as_at_start():
    """An entry point run in-process may leave SIGINT or SIGTERM ignored after its stop (a child process would
    inherit that and not stop on it): each test starts with Python's own handlers."""
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    yield


@pytest.fixture(autouse=True)
def _restore_logging():
    """A Hydra main run in-process (``--help``, ``--version``) configures the root logger with handlers
    on that test's captured streams; put the handlers back so later tests do not write to closed ones."""
    loggers = [logging.getLogger(), logging.getLogger("lit3d")]
    saved = [(lg, lg.handlers[:], lg.level) for lg in loggers]
    yield
    for lg, handlers, level in saved:
        lg.handlers[:] = handlers
        lg.setLevel(level)


@pytest.fixture
def readonly_dir(tmp_path):
    """A folder no file can be written into: chmod 555, or (as root, who ignores modes) a read-only
    tmpfs mounted on it; skipped where neither works."""
    d = tmp_path / "ro"
    d.mkdir()
    if os.geteuid() != 0:
        d.chmod(0o555)
        yield d
        d.chmod(0o755)
        return
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=64k", "tmpfs", str(d)],
                      capture_output=True).returncode != 0:
        pytest.skip("running as root and cannot mount a read-only tmpfs")
    try:
        yield d
    finally:
        subprocess.run(["umount", str(d)], check=False)
