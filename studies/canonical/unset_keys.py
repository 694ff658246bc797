"""Which settings of the canonical task's config, and of its DataModule, no config sets.

    python -m studies.canonical.unset_keys [--all]

The keys are the leaves of ``lit3d/conf/task/canonical.yaml`` under its nodes ``task_info``, ``task`` and
``evaluation``, dotted (``task.net.head.kind``; a list is one leaf), less what names the task
(``task_info.name``, ``task._target_``) and interpolations of other keys (``task.net.image_size``). A key is set when a file of

    lit3d/conf/experiment/canonical_*.yaml       its nodes, flattened the same way
    sweeps/canonical*.yaml                       its nodes and its ``hydra.sweeper.params`` (``task.x.y: a,b``)
    lit3d/conf/hparams_search/canonical*.yaml    the same

sets it or a node above it. The data keys are the fields of the DataModule's settings
(:mod:`datamodules.canonical.settings`: ``data.render.*``, ``data.split.*``, ``data.training.*``, and
``data.source.<field> (<kind>)`` for each source kind) and its other constructor arguments (``data.batch_size``);
one is set when a file above sets it or when a data config (:data:`DATA_CONFIGS`, their keys under ``data.``)
does, a source field only by a data config of that source kind (or a file above, whatever the kind).

Prints the task keys no file sets that the "Supported options" table of ``docs/results_canonical.md`` does not
list (``--all``: every key no file sets, the table's marked ``*``), then ``N of M keys set by no experiment`` and
``K of them not in the supported-options table``; then the same for the data keys (``N of M data keys set by no
config``). A file that is not a YAML mapping: one line naming it, exit status 2.
"""
from __future__ import annotations

import argparse
import dataclasses
import inspect
import re
import sys
from collections.abc import Iterator
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[2]
TASK_CONFIG = Path("lit3d/conf/task/canonical.yaml")
TASK_NODES = ("task_info", "task", "evaluation")
SETTING_FILES = ("lit3d/conf/experiment/canonical_*.yaml", "sweeps/canonical*.yaml", "lit3d/conf/hparams_search/canonical*.yaml")
OPTIONS_PAGE = Path("docs/results_canonical.md")
OPTIONS_HEADING = "## Supported options"
NOT_SETTINGS = ("defaults", "hydra")  # nodes of a setting file that are not config values (params: read apart)
NOT_OPTIONS = ("task_info.name", "task._target_")  # what the task is, not how it runs
# the canonical data configs (package data: their keys are under data.); views: the experiments' shared view settings
DATA_CONFIGS = (*(f"lit3d/conf/data/{name}.yaml" for name in ("canonical_synth", "anny", "tosca", "shrec14", "faust",
                                                               "sumner")), "lit3d/conf/data/views/*.yaml")
DATA_NODES = ("render", "split", "training")  # data.source: one node per source kind


class ConfigFileError(ValueError):
    """A config or docs file that cannot be read as this script needs it; the message names the file."""


def leaves(node, prefix: str = "", values: bool = False) -> Iterator:
    """Dotted paths of the leaves of a nested mapping (a list or a scalar is a leaf); ``values``: (path, value)."""
    if isinstance(node, dict) and node:
        for key, value in node.items():
            yield from leaves(value, f"{prefix}.{key}" if prefix else str(key), values)
    elif prefix:
        yield (prefix, node) if values else prefix


def shown(path: Path) -> str:
    """``path`` relative to the checkout when it is inside it."""
    return str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path)


def read_mapping(path: Path) -> dict:
    """``path`` parsed as a YAML mapping (an empty file: {}); ConfigFileError naming it otherwise."""
    try:
        data = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as err:
        raise ConfigFileError(f"{shown(path)}: not readable as YAML ({str(err).splitlines()[0]})") from err
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ConfigFileError(f"{shown(path)}: expected a YAML mapping, got {type(data).__name__}")
    return data


def task_keys(root: Path = ROOT) -> list[str]:
    """The dotted leaves of the task config's :data:`TASK_NODES`, in file order, less :data:`NOT_OPTIONS` and
    those whose value is an interpolation of another key (``${...}``: set where that key is)."""
    config = read_mapping(root / TASK_CONFIG)
    return [key for node in TASK_NODES if node in config for key, value in leaves(config[node], node, values=True)
            if key not in NOT_OPTIONS and not (isinstance(value, str) and value.startswith("${"))]


def keys_set_by(path: Path) -> set[str]:
    """The dotted keys one experiment, sweep or search file sets: its value nodes flattened, and the keys of its
    ``hydra.sweeper.params`` (``+``/``++``/``~`` prefixes stripped)."""
    data = read_mapping(path)
    found = {key for name, node in data.items() if name not in NOT_SETTINGS for key in leaves(node, str(name))}
    params = (((data.get("hydra") or {}).get("sweeper") or {}).get("params")) or {}
    if not isinstance(params, dict):
        raise ConfigFileError(f"{shown(path)}: hydra.sweeper.params is not a mapping")
    return found | {str(key).lstrip("+~") for key in params}


def setting_files(root: Path = ROOT) -> list[Path]:
    """Every experiment, sweep and search file of :data:`SETTING_FILES`, sorted."""
    return sorted(path for pattern in SETTING_FILES for path in root.glob(pattern))


def unset_keys(root: Path = ROOT) -> tuple[list[str], list[str]]:
    """(every key of :func:`task_keys`, those that no setting file sets, nor a node above them)."""
    keys = task_keys(root)
    given = set().union(*(keys_set_by(path) for path in setting_files(root)))
    return keys, [key for key in keys if not covered(key, given)]


def covered(key: str, given: set[str]) -> bool:
    """Whether ``given`` holds the dotted ``key`` or a node above it (``task.net`` covers ``task.net.init``)."""
    parts = key.split(".")
    return any(".".join(parts[:i]) in given for i in range(1, len(parts) + 1))


def data_keys() -> list[str]:
    """The canonical DataModule's settings as dotted keys: its constructor's arguments but the nodes
    (``data.batch_size``), ``data.source.<field> (<kind>)`` for every field of every source kind, and the fields
    of :data:`DATA_NODES` (``data.render.flow_targets``), in the code's order."""
    from datamodules.canonical import CanonicalDataModule
    from datamodules.canonical import settings

    nodes = {"source", *DATA_NODES}
    keys = [f"data.{name}" for name in list(inspect.signature(CanonicalDataModule.__init__).parameters)[1:]
            if name not in nodes]
    keys += [f"data.source.{f.name} ({kind})" for kind, cls in settings.SOURCE_SETTINGS.items()
             for f in dataclasses.fields(cls)]
    classes = {"render": settings.RenderSettings, "split": settings.SplitSettings, "training": settings.TrainingSettings}
    return keys + [f"data.{node}.{f.name}" for node in DATA_NODES for f in dataclasses.fields(classes[node])]


def dotted(key: str) -> str:
    """A data key without its source kind (``data.source.classes (tosca)`` -> ``data.source.classes``)."""
    return key.split(" (")[0]


def data_configs(root: Path = ROOT) -> list[Path]:
    """Every data config of :data:`DATA_CONFIGS` under ``root``, sorted; ConfigFileError for a named one missing."""
    found = []
    for pattern in DATA_CONFIGS:
        paths = sorted(root.glob(pattern))
        if not paths and "*" not in pattern:
            raise ConfigFileError(f"{pattern}: no such data config")
        found += paths
    return sorted(found)


def unset_data_keys(root: Path = ROOT) -> tuple[list[str], list[str]]:
    """(every key of :func:`data_keys`, those that no setting file nor data config sets, nor a node above them;
    a source field counts as set by a data config of its own kind only)."""
    keys = data_keys()
    given = set().union(*(keys_set_by(path) for path in setting_files(root)))
    by_kind: dict[str, set[str]] = {}
    for path in data_configs(root):
        config = {name: node for name, node in read_mapping(path).items() if name not in NOT_SETTINGS}
        source = config.pop("source", None)
        given |= set(leaves(config, "data"))
        if source is not None:
            kind = source.get("kind") if isinstance(source, dict) else None
            if not isinstance(kind, str):
                raise ConfigFileError(f"{shown(path)}: its source node has no kind")
            by_kind.setdefault(kind, set()).update(leaves(source, "data.source"))
    return keys, [key for key in keys
                  if not covered(dotted(key), given | by_kind.get(key.partition(" (")[2].rstrip(")"), set()))]


def documented_keys(root: Path = ROOT) -> list[str]:
    """The keys in the first column of the table under :data:`OPTIONS_HEADING` of :data:`OPTIONS_PAGE`
    (backquoted, ``task.x.y``, ``data.x.y``); ConfigFileError naming the page when it has no such section or table."""
    page = root / OPTIONS_PAGE
    try:
        lines = page.read_text().splitlines()
    except OSError as err:
        raise ConfigFileError(f"{shown(page)}: not readable ({err.strerror})") from err
    if OPTIONS_HEADING not in lines:
        raise ConfigFileError(f"{shown(page)}: no '{OPTIONS_HEADING}' section")
    keys: list[str] = []
    for line in lines[lines.index(OPTIONS_HEADING) + 1:]:
        if line.startswith("## "):
            break
        match = re.match(r"\|\s*`([\w.]+)`\s*\|", line)
        if match:
            keys.append(match.group(1))
    if not keys:
        raise ConfigFileError(f"{shown(page)}: the '{OPTIONS_HEADING}' section has no table rows of `keys`")
    return keys


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--all", action="store_true", help="list every key no file sets, documented ones marked *")
    args = parser.parse_args(argv)
    try:
        keys, unset = unset_keys()
        all_data, unset_data = unset_data_keys()
    except ConfigFileError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    try:
        documented = set(documented_keys())
    except ConfigFileError as err:  # the counts still stand; the table is what is missing
        print("\n".join(unset))
        print(f"{len(unset)} of {len(keys)} keys set by no experiment")
        print("\n".join(unset_data))
        print(f"{len(unset_data)} of {len(all_data)} data keys set by no config")
        print(f"error: {err}", file=sys.stderr)
        return 2
    for unset_here, total, what in ((unset, keys, "keys set by no experiment"),
                                    (unset_data, all_data, "data keys set by no config")):
        undocumented = [key for key in unset_here if dotted(key) not in documented]
        for key in unset_here if args.all else undocumented:
            print(f"{key}{' *' if dotted(key) in documented else ''}")
        print(f"{len(unset_here)} of {len(total)} {what}")
        print(f"{len(undocumented)} of them not in the supported-options table ({OPTIONS_PAGE})")
    return 0

if __name__ == "__main__":
    raise SystemExit(main())
