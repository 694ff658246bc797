"""Which settings of the canonical task's config no experiment, sweep or hyper-parameter search sets.

    python -m studies.canonical.unset_keys [--all]

The keys are the leaves of ``lit3d/conf/task/canonical.yaml`` under its nodes ``task_info``, ``task`` and
``evaluation``, dotted (``task.net.head.kind``; a list is one leaf), less what names the task
(``task_info.name``, ``task._target_``) and interpolations of other keys (``task.net.image_size``). A key is set when a file of

    lit3d/conf/experiment/canonical_*.yaml       its nodes, flattened the same way
    sweeps/canonical*.yaml                       its nodes and its ``hydra.sweeper.params`` (``task.x.y: a,b``)
    lit3d/conf/hparams_search/canonical*.yaml    the same

sets it or a node above it. Prints the keys no file sets that the "Supported options" table of
``docs/results_canonical.md`` does not list (``--all``: every key no file sets, the table's marked ``*``), then
``N of M keys set by no experiment`` and ``K of them not in the supported-options table``.
A file that is not a YAML mapping: one line naming it, exit status 2.
"""
from __future__ import annotations

import argparse
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
    def is_set(key: str) -> bool:
        parts = key.split(".")
        return any(".".join(parts[:i]) in given for i in range(1, len(parts) + 1))
    return keys, [key for key in keys if not is_set(key)]


def documented_keys(root: Path = ROOT) -> list[str]:
    """The keys in the first column of the table under :data:`OPTIONS_HEADING` of :data:`OPTIONS_PAGE`
    (backquoted, ``task.x.y``); ConfigFileError naming the page when it has no such section or table."""
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
    except ConfigFileError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    try:
        documented = set(documented_keys())
    except ConfigFileError as err:  # the counts still stand; the table is what is missing
        print("\n".join(unset))
        print(f"{len(unset)} of {len(keys)} keys set by no experiment")
        print(f"error: {err}", file=sys.stderr)
        return 2
    undocumented = [key for key in unset if key not in documented]
    for key in unset if args.all else undocumented:
        print(f"{key}{' *' if key in documented else ''}")
    print(f"{len(unset)} of {len(keys)} keys set by no experiment")
    print(f"{len(undocumented)} of them not in the supported-options table ({OPTIONS_PAGE})")
    return 0

if __name__ == "__main__":
    raise SystemExit(main())
