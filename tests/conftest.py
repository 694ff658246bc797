"""Shared fixtures: Hydra config composition with per-test output dirs."""
from __future__ import annotations

import logging
import os
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
    """The entry points' filters for what lit3d cannot fix (lit3d.utils.quiet), in every test."""
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


def square_subjects(n: int = 8, size: int = 32, classes: int = 4):
    """A toy subject-recognition batch: ``(depth (n,1,size,size), mask, subject_idx (n,))``, subject k a
    filled square of side 6 + 3k (depth .5) at a random place (seeded): what tells them apart is the size."""
    import torch

    g = torch.Generator().manual_seed(0)
    depth, idx = torch.zeros(n, 1, size, size), torch.arange(n) % classes
    for i in range(n):
        s = 6 + 3 * int(idx[i])
        x, y = torch.randint(0, size - s, (2,), generator=g).tolist()
        depth[i, 0, y:y + s, x:x + s] = 0.5
    return depth, (depth > 0).float(), idx


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
