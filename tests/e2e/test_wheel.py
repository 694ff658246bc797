"""``pip install .`` (not editable) gives a working lit3d: the wheel ships the Hydra configs, the licence and py.typed.

The wheel is built from a copy of the sources (no ``build/`` in the checkout), installed into a fresh venv
that sees the project venv's dependencies but not its editable lit3d, and ``lit3d-train`` runs a tiny
completion fast-dev-run from a directory outside the checkout.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
import tomllib
import zipfile
from pathlib import Path

import pytest
from tests.helpers.paths import REPO

# what the build reads: pyproject's packages, readme and licence, and the targets of lit3d/conf -> ../conf
# and conf/sweep -> ../sweeps
SOURCES = ["pyproject.toml", "README.md", "LICENSE", "lit3d", "datamodules", "conf", "sweeps"]
TINY = [  # tests/e2e/test_completion_cli.py's sizes
    "experiment=completion_demo",
    "data.sizes={train:16,val:8,test_same:8,test_cross:8,test_unseen:8}",
    "data.batch_size=4",
    "callbacks.progress_bar=null",
]


def _run(args: list, cwd: Path, timeout: int = 300, **env) -> subprocess.CompletedProcess:
    base = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    res = subprocess.run([str(a) for a in args], cwd=cwd, env={**base, **env}, capture_output=True, text=True,
                         timeout=timeout)
    assert res.returncode == 0, f"{args}\n{res.stdout[-3000:]}\n{res.stderr[-3000:]}"
    return res


def _repo_configs() -> set[str]:
    """Every config under conf/, as the wheel must hold it (through conf/sweep -> ../sweeps)."""
    conf = REPO / "conf"
    found = set()
    for root, _, files in os.walk(conf, followlinks=True):
        found |= {(Path(root) / f).relative_to(conf).as_posix() for f in files if f.endswith(".yaml")}
    return found


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("wheel")
    src = tmp / "src"
    src.mkdir()
    for name in SOURCES:
        path = REPO / name
        if path.is_dir() and not path.is_symlink():
            shutil.copytree(path, src / name, symlinks=True,
                            ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info"))
        else:
            shutil.copy2(path, src / name, follow_symlinks=False)
    # the venv's setuptools (no download), no dependencies: only lit3d's own wheel
    _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--no-index",
          "--disable-pip-version-check", "-q", "-w", tmp / "dist", src], cwd=tmp)
    (whl,) = (tmp / "dist").glob("lit3d-*.whl")
    return whl


def test_wheel_ships_configs_license_and_py_typed(wheel):
    with zipfile.ZipFile(wheel) as z:
        names = set(z.namelist())
        (metadata,) = [n for n in names if n.endswith(".dist-info/METADATA")]
        meta = z.read(metadata).decode()
    assert "lit3d/py.typed" in names
    assert "License-Expression: MIT" in meta.splitlines() and "License-File: LICENSE" in meta.splitlines()
    license_file = metadata.replace("METADATA", "licenses/LICENSE")
    assert license_file in names
    configs = {n.removeprefix("lit3d/conf/") for n in names if n.startswith("lit3d/conf/")}
    assert configs == _repo_configs()
    assert {"train.yaml", "eval.yaml", "experiment/completion_demo.yaml", "debug/fdr.yaml",
            "sweep/completion_classifier.yaml"} <= configs
    assert not any(n.startswith("conf/") for n in names), "configs only inside the lit3d package"


# extra -> a requirement it adds, which the base install does not have
EXTRA_REQUIREMENTS = {"body": "anny", "slurm": "hydra-submitit-launcher", "wandb": "wandb", "tensorboard": "tensorboard",
                      "optuna": "hydra-optuna-sweeper"}
URL_LABELS = {"Homepage", "Documentation", "Source", "Changelog", "Citation"}


def test_wheel_metadata_names_the_project_urls_and_the_extras(wheel):
    """``pip show``/an index page link the repository (CITATION.cff's repository-code), and the heavy
    features are extras: ``Requires-Dist: anny...; extra == "body"``, not in the base requirements."""
    import email.parser
    import re

    with zipfile.ZipFile(wheel) as z:
        (metadata,) = [n for n in z.namelist() if n.endswith(".dist-info/METADATA")]
        meta = email.parser.Parser().parsestr(z.read(metadata).decode())
    repo = re.search(r'^repository-code: "([^"]+)"$', (REPO / "CITATION.cff").read_text(), re.M).group(1)
    urls = dict(u.split(", ", 1) for u in meta.get_all("Project-URL"))
    assert set(urls) == URL_LABELS and all(u.startswith(repo) for u in urls.values()), urls
    assert urls["Source"] == repo
    for label in ("Changelog", "Citation"):  # the files they name are the project's own
        assert (REPO / urls[label].removeprefix(f"{repo}/blob/main/")).is_file(), urls[label]
    assert set(meta.get_all("Provides-Extra")) == {*EXTRA_REQUIREMENTS, "all", "dev"}
    requires = meta.get_all("Requires-Dist")
    base = {re.match(r"[\w.-]+", r).group(0).lower() for r in requires if "extra ==" not in r}
    assert {"torch", "lightning", "hydra-core", "trimesh", "pyrender"} <= base
    for extra, package in EXTRA_REQUIREMENTS.items():
        assert package not in base, f"{package} is in the base install; expected only with lit3d[{extra}]"
        assert any(r.startswith(package) and f'extra == "{extra}"' in r for r in requires), (extra, requires)
    assert any(r.startswith("roma") and 'extra == "body"' in r for r in requires)
    assert any(r.startswith("lit3d[") and 'extra == "all"' in r for r in requires)


def test_installed_wheel_trains_outside_the_checkout(wheel, tmp_path):
    assert not tmp_path.resolve().is_relative_to(REPO)
    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", venv], cwd=tmp_path)
    python = venv / "bin" / "python"
    site = Path(_run([python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                     cwd=tmp_path).stdout.strip())
    # the dependencies (and pip) from this venv: a plain path line, so its .pth files, among them the
    # editable install's finder of lit3d, are not run
    deps = dict.fromkeys(str(Path(sysconfig.get_paths()[k]).resolve()) for k in ("purelib", "platlib"))
    (site / "_lit3d_test_deps.pth").write_text("".join(f"{d}\n" for d in deps))
    _run([python, "-m", "pip", "install", "--no-deps", "--no-index", "--ignore-installed",
          "--disable-pip-version-check", "-q", wheel], cwd=tmp_path)

    where = _run([python, "-c", "import lit3d, lit3d.runtime.compose as c; print(lit3d.__file__); print(c.CONF_DIR)"],
                 cwd=tmp_path).stdout.split()
    assert Path(where[0]).resolve() == (site / "lit3d" / "__init__.py").resolve()
    assert Path(where[1]).resolve() == (site / "lit3d" / "conf").resolve()

    work = tmp_path / "work"
    work.mkdir()
    out = work / "run"
    _run([venv / "bin" / "lit3d-train", *TINY, "debug=fdr", f"hydra.run.dir={out}"], cwd=work, timeout=600,
         WANDB_MODE="offline", WANDB_SILENT="true", HYDRA_FULL_ERROR="1")
    metrics = json.loads((out / "metrics.json").read_text())
    assert "test/same/iou" in metrics
    # provenance (lit3d.utils.provenance): the wheel's version; no git commit outside a checkout
    assert metrics["provenance"]["lit3d_version"] == tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["version"]
    assert metrics["provenance"]["git_commit"] is None and metrics["provenance"]["manifest_hash"]
    assert (work / "data" / "completion_demo").is_dir(), "paths.root_dir '.': the data next to the run"
