"""What keeps a prepared cache honest (used by :mod:`datamodules.cache`; no lit3d imports here).

- :func:`config_difference`: which keys of a folder's recorded config differ from this run's
  (the one line of the refusal to overwrite a cache of another config).
- :func:`manifest_problem`: the cheap check of a manifest on load: its ``manifest_hash`` is the
  hash of its own items (a hand-edited manifest fails), every item file is there and has the
  size recorded in ``item_bytes`` (a truncated or replaced item fails).
- :func:`watch` / :func:`changed`: the caches this process has read, and whether one changed
  on disk since (another process re-prepared the folder while a training reads it).
  ``changed`` costs one ``stat`` of ``manifest.json`` (plus one per item with ``items=True``).

Functions here return a problem (a phrase) or None; :mod:`datamodules.cache` turns it into a
:class:`~datamodules.cache.DataError` naming the folder.
"""
from __future__ import annotations

import json
import os
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

MANIFEST = "manifest.json"
SHOWN = 3  # differing keys named in the refusal line


def _flat(obj, prefix: str = "") -> dict[str, object]:
    """Nested dicts as dotted keys (``{"sizes": {"train": 8}}`` -> ``{"sizes.train": 8}``)."""
    if not isinstance(obj, dict):
        return {prefix: obj}
    out: dict[str, object] = {}
    for k, v in obj.items():
        out.update(_flat(v, f"{prefix}.{k}" if prefix else str(k)))
    return out


def config_difference(recorded: dict | None, generator: str, version: str, config: dict) -> str:
    """``"sizes.train: 8 here, 800 there; ..."``: how this run's (generator, version, config)
    differs from what ``recorded`` (a manifest or ``prepare.json``) says; "" when nothing differs
    that can be named."""
    if not recorded:
        return "item files of unknown origin (no manifest.json or prepare.json)"
    if recorded.get("generator") != generator:
        return f"generator: {generator} here, {recorded.get('generator') or 'an older lit3d layout'} there"
    if str(recorded.get("version")) != str(version):
        return f"{generator} version: {version} here, {recorded.get('version')} there"
    if not isinstance(recorded.get("config"), dict):
        return "config: not recorded there"
    have, want = _flat(recorded["config"]), _flat(config)
    keys = sorted(k for k in set(have) | set(want) if have.get(k, "(unset)") != want.get(k, "(unset)"))
    parts = [f"{k}: {want.get(k, '(unset)')} here, {have.get(k, '(unset)')} there" for k in keys[:SHOWN]]
    if len(keys) > SHOWN:
        parts.append(f"and {len(keys) - SHOWN} more")
    return "; ".join(parts)


def manifest_problem(root: Path, manifest: dict, items_hash: str) -> tuple[str | None, list[str]]:
    """``(problem, bad_files)`` of a manifest read from ``root``: ``items_hash`` (the hash of its
    ``items`` as they are now) must equal its ``manifest_hash``; each item file must exist and,
    where ``item_bytes`` records it, have that size. ``bad_files``: the items to make again."""
    sizes = manifest.get("item_bytes") or {}
    bad, problems = [], []
    recorded = manifest.get("manifest_hash")
    if recorded is not None and recorded != items_hash:
        problems.append(f"{MANIFEST} was edited: its items no longer match its manifest_hash "
                        f"({str(recorded)[:12]}; the items hash to {items_hash[:12]})")
    for it in manifest.get("items", []):
        rel = it["file"]
        try:
            n = (root / rel).stat().st_size
        except OSError:
            bad.append(rel)
            problems.append(f"{rel}: missing")
            continue
        want = sizes.get(rel)
        if want is not None and n != want:
            bad.append(rel)
            problems.append(f"{rel}: {n} bytes, the manifest says {want} (truncated or replaced)")
    return (problems[0] if problems else None), bad


# ------------------------------------------------------------------ caches in use by this process
@dataclass
class _Watch:
    root: Path
    manifest_hash: str
    stamp: tuple
    sizes: dict = field(default_factory=dict)
    read_at: float = 0.0


_WATCHED: dict[str, _Watch] = {}
_GUARD = threading.Lock()


def _stamp(path: Path) -> tuple | None:
    try:
        st = path.stat()
    except OSError:
        return None
    return st.st_ino, st.st_mtime_ns, st.st_size


def watch(root: Path, manifest: dict) -> None:
    """Remember ``root``'s manifest as this process read it (verified) just now."""
    stamp = _stamp(root / MANIFEST)
    if stamp is None or manifest.get("manifest_hash") is None:
        return
    with _GUARD:
        _WATCHED[str(Path(root).resolve())] = _Watch(Path(root), manifest["manifest_hash"], stamp,
                                                     dict(manifest.get("item_bytes") or {}), time.monotonic())


def changed(since: float = 0.0, items: bool = True) -> str | None:
    """The first cache read by this process at or after ``since`` (``time.monotonic()``) that is
    no longer what it read: ``"<folder>: <what changed>"``; None when all are unchanged."""
    with _GUARD:
        watched = [w for w in _WATCHED.values() if w.read_at >= since]
    for w in watched:
        path = w.root / MANIFEST
        stamp = _stamp(path)
        if stamp is None:
            return f"{w.root}: {MANIFEST} was removed while this run read the data (another process is re-preparing it)"
        if stamp != w.stamp:
            try:
                now = json.loads(path.read_text("utf-8")).get("manifest_hash")
            except (OSError, json.JSONDecodeError, AttributeError):
                now = None
            if now != w.manifest_hash:
                return (f"{w.root}: the prepared data changed while this run read it (manifest_hash "
                        f"{w.manifest_hash[:12]} -> {str(now)[:12]}: another process re-prepared the folder)")
            w.stamp = stamp
        if items:
            for rel, n in w.sizes.items():
                try:
                    size = os.stat(w.root / rel).st_size
                except OSError:
                    size = None
                if size != n:
                    return (f"{w.root / rel}: changed while this run read the data ({n} bytes before, "
                            f"{'gone' if size is None else f'{size} bytes'} now: another process re-prepared the folder)")
    return None
