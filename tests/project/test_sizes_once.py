"""Sizes are written once, in the configs.

- No net or DataModule constructor carries a size default: a size-named parameter (grid, image size,
  channels, widths; not the batch size) either has no default or defaults to "off" (None or an empty sequence), so a size
  the configs forget is an error instead of a silent demo-scale value.
- What is one fact is interpolated: the canonical net's image size is the data's, the completion nets'
  grids are the data's target grid and target grid / input factor, in every experiment.
"""
from __future__ import annotations

import importlib
import inspect
import pkgutil
import re

import lightning as L
import pytest
import torch.nn as nn
from omegaconf import OmegaConf

import datamodules
import lit3d
from lit3d.utils.config_dir import config_dir, exact_quotient

SIZE_NAME = re.compile(r"(^|_)(res|size|channels|grid|hidden|dim|out|cin|width|height)$")
NOT_SIZES = {"batch_size"}  # a loading setting of the DataModules (configs set it), not a tensor size
ROOMS = ("lit3d.canonical", "lit3d.completion", "lit3d.quality", "datamodules")
OFF = (None, (), [], 0)  # "off": no such part (e.g. the warp head without a latent)


def _classes():
    """Every nn.Module and LightningDataModule defined in the task rooms and the data packages."""
    found = {}
    for pkg in (lit3d, datamodules):
        for info in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + "."):
            if not info.name.startswith(ROOMS):
                continue
            mod = importlib.import_module(info.name)
            for obj in vars(mod).values():
                if (inspect.isclass(obj) and obj.__module__ == mod.__name__
                        and issubclass(obj, (nn.Module, L.LightningDataModule))):
                    found[f"{obj.__module__}.{obj.__qualname__}"] = obj
    return found


def size_defaults(cls) -> list[str]:
    """``name=default`` for each size-named constructor parameter of ``cls`` with a default that is not off."""
    sig = inspect.signature(cls.__init__)
    return [f"{p.name}={p.default!r}" for p in sig.parameters.values()
            if SIZE_NAME.search(p.name) and p.name not in NOT_SIZES and p.default is not inspect.Parameter.empty
            and p.default not in OFF]


def test_the_check_finds_a_size_default():
    class Sneaky(nn.Module):
        def __init__(self, channels=(8, 16), image_size: int = 128, hidden: int | None = None, dropout: float = 0.1):
            super().__init__()

    assert size_defaults(Sneaky) == ["channels=(8, 16)", "image_size=128"]


def test_no_net_or_datamodule_constructor_has_a_size_default():
    classes = _classes()
    assert {"lit3d.canonical.nets.MSFE", "lit3d.completion.generator.CascadeGenerator",
            "datamodules.canonical.datamodule.CanonicalDataModule",
            "datamodules.completion.datamodule.CompletionDataModule"} <= set(classes)
    offenders = {name: bad for name, cls in classes.items() if (bad := size_defaults(cls))}
    assert not offenders, f"size defaults in constructors (put them in conf/): {offenders}"


def _experiments(prefix: str) -> list[str]:
    return sorted(p.stem for p in (config_dir() / "experiment").glob(f"{prefix}_*.yaml"))


@pytest.mark.parametrize("experiment", _experiments("canonical"))
def test_canonical_net_reads_the_data_image_size(compose_cfg, experiment):
    cfg = compose_cfg([f"experiment={experiment}"])
    assert OmegaConf.to_container(cfg.task.net)["image_size"] == "${oc.select:data.image_size,null}"
    assert cfg.task.net.image_size == cfg.data.image_size


def test_one_data_override_moves_the_net_sizes(compose_cfg):
    assert compose_cfg(["experiment=canonical_tiny", "data.image_size=40"]).task.net.image_size == 40
    nets = compose_cfg(["experiment=completion_demo", "data.target_res=32"]).task.nets
    assert (nets.in_res, nets.out_res) == (8, 32)


@pytest.mark.parametrize("experiment", _experiments("completion"))
def test_completion_nets_read_the_data_grids(compose_cfg, experiment):
    cfg = compose_cfg([f"experiment={experiment}"])
    assert cfg.task.nets.out_res == cfg.data.target_res
    assert cfg.task.nets.in_res * cfg.data.input_factor == cfg.data.target_res


def test_exact_quotient_refuses_a_remainder():
    assert exact_quotient(256, 4) == 64
    with pytest.raises(ValueError, match="63 is not a whole multiple of 4"):
        exact_quotient(63, 4)
    assert exact_quotient(None, 4) is None  # a config without data (lit3d-eval task=NAME)
