"""Generic on-disk cache pieces shared by every lit3d DataModule.

- :class:`DataError`: a bad input file or setting, one message naming the file/setting.
- :func:`stable_hash` / :func:`stable_seed`: hashes and RNG seeds that do not depend
  on Python's per-process ``hash()`` salt.
- :func:`atomic_save_npz`: arrays -> ``.npz`` through a temp file + ``os.replace``.
- :class:`CacheBuilder`: the preparation protocol. A ``prepare.json`` marker (generator,
  version, config hash of the item files in the folder) is written first and kept,
  items are written atomically one by one, ``manifest.json`` is written last
  (atomically). Re-running skips items already on disk (also when the manifest was
  deleted). A folder holding a marker or manifest of another config/version, or item
  files of unknown origin, is refused with one line naming what differs (:class:`DataError`);
  nothing is deleted unless this process asked for it (:func:`request_rebuild`, i.e.
  ``lit3d-data ... --rebuild``), so a cache never mixes two configs and no evaluation or
  training wipes another config's data. A manifest is checked when it is read (its hash
  against its items, each item's size against ``item_bytes``: a hand edit or a truncated item
  is named, and ``prepare_data()`` repairs it); :func:`check_unchanged` tells a running
  training that another process re-prepared its folder (:mod:`datamodules.cache_guard`).
  :meth:`CacheBuilder.locked` holds an inter-process lock (``flock`` on ``<root>/.lock``)
  around a preparation: processes preparing one folder at once (the jobs of a multirun)
  take turns, and the later ones find the cache complete. :meth:`CacheBuilder.prepare_once` is
  that locked, double-checked preparation, written once: every DataModule's ``prepare_data()``
  calls it with a function that writes the items and returns them.

Manifest layout (``manifest.json``)::

    {"generator": str, "version": str, "config": {...}, "config_hash": sha256,
     "items": [{"file": "items/...npz", "sha256": of the file's bytes, "split": ..., ...}, ...],
     "manifest_hash": sha256 of the canonical JSON of "items", "item_bytes": {file: size}, ...extra}

Because every item carries the hash of its bytes, two preparations have the same
``manifest_hash`` exactly when they wrote the same files (same seed -> same hash).
"""
from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import os
import shutil
import threading
import zlib
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from datamodules.cache_guard import changed, config_difference, manifest_problem, watch
from datamodules.cache_lock import flock_waiting, funlock
from lit3d.utils.errors import Lit3dError
from lit3d.utils.io import atomic_file, atomic_write_bytes, file_sha256, remove_temp_files, write_json
from lit3d.utils.stops import StopRequested, check_stop

log = logging.getLogger("lit3d.data")

MANIFEST = "manifest.json"
MARKER = "prepare.json"
LOCK = ".lock"

__all__ = [
    "LOCK", "MANIFEST", "MARKER", "CacheBuilder", "DataError", "atomic_save_npz", "atomic_write_bytes",
    "check_unchanged", "clean_temp_files", "file_sha256", "read_manifest", "request_rebuild", "stable_hash",
    "stable_int_seed", "stable_seed", "write_json",
]

# ``lit3d-data --rebuild``: every cache this process prepares is deleted and made again, once
_REBUILD: dict = {"on": False, "done": set()}


class DataError(Lit3dError, ValueError):
    """A bad data file or data setting; the message names the file (or setting) and the problem."""


def request_rebuild(on: bool = True) -> None:
    """Let this process delete and prepare again every cache folder it prepares (once each), also
    one of another config (``lit3d-data ... --rebuild``); without it such a folder is refused."""
    _REBUILD["on"] = bool(on)
    _REBUILD["done"].clear()


def _rebuild_pending(root: Path) -> bool:
    return _REBUILD["on"] and str(root.resolve()) not in _REBUILD["done"]


def check_unchanged(since: float = 0.0, items: bool = True) -> None:
    """Raise :class:`DataError` when a cache this process read (at or after ``since``, a
    ``time.monotonic()``) changed on disk since: its manifest was replaced by another one or
    removed, or (``items``) an item file changed size. One ``stat`` per cache (+ one per item)."""
    problem = changed(since, items)
    if problem:
        raise DataError(f"{problem}; start the run again")


def canonical_json(obj: Any) -> str:
    """JSON with sorted keys and no whitespace: the form that is hashed."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), default=str)


def stable_hash(obj: Any) -> str:
    """sha256 hex digest of the canonical JSON of ``obj``."""
    return hashlib.sha256(canonical_json(obj).encode("utf-8")).hexdigest()


def stable_seed(*parts: int | str) -> np.random.SeedSequence:
    """A numpy SeedSequence from ints and strings (strings via crc32, stable across processes)."""
    ints = [p if isinstance(p, int) else zlib.crc32(str(p).encode("utf-8")) for p in parts]
    return np.random.SeedSequence([int(i) & 0xFFFFFFFF for i in ints])


def stable_int_seed(*parts: object) -> int:
    """A 31-bit int seed from strings/ints (crc32 of ``"a|b|c"``), stable across processes; the
    quality data's distortion and shape seeds (their caches were made with it)."""
    return zlib.crc32("|".join(str(p) for p in parts).encode()) & 0x7FFFFFFF


def atomic_save_npz(path: str | os.PathLike, compress: bool = True, **arrays: np.ndarray) -> Path:
    """Save ``arrays`` as ``path`` (.npz) via a temp file in the same folder + ``os.replace``
    (:func:`lit3d.utils.io.atomic_file`: an OSError, a full disk's included, names ``path``).

    An interrupted write leaves only a ``.<name>.*.tmp`` file, which
    :func:`clean_temp_files` removes; ``path`` is either absent or complete.
    """
    with atomic_file(path) as f:
        (np.savez_compressed if compress else np.savez)(f, **arrays)
    return Path(path)


clean_temp_files = remove_temp_files  # leftover ``.*.tmp`` files of interrupted writes


def read_manifest(root: str | os.PathLike) -> dict | None:
    """The manifest in ``root`` or None when there is none; a corrupt one raises :class:`DataError`."""
    path = Path(root) / MANIFEST
    if not path.is_file():
        return None
    try:
        return json.loads(path.read_text("utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise DataError(f"{path}: unreadable manifest ({exc}); delete it to re-prepare the data") from exc


class CacheBuilder:
    """Resumable, atomic preparation of a cache folder of item files + manifest.

    Usage (:meth:`prepare_once` runs the lock, the checks, :meth:`begin` and :meth:`finish`)::

        def write_items(b: CacheBuilder) -> tuple[list[dict], dict]:
            for item in items:
                if not b.has(item["file"]):  # resume: items already on disk are kept
                    atomic_save_npz(b.path(item["file"]), ...)
            return items, {...}              # the manifest's items and extra keys

        b = CacheBuilder(root, generator="completion_synth", version="1", config=cfg)
        b.prepare_once(write_items)
        manifest = b.manifest()
    """

    # (root, thread) -> depth of the locks this process holds: a nested ``locked()`` of the same
    # folder in the same thread does not wait for itself (flock locks are per open file)
    _held: dict[tuple[str, int], int] = {}
    _held_guard = threading.Lock()

    def __init__(self, root: str | os.PathLike, generator: str, version: str, config: dict,
                 items_dir: str = "items"):
        self.root = Path(root)
        self.generator, self.version = generator, str(version)
        self.config = config
        self.config_hash = stable_hash({"generator": generator, "version": self.version, "config": config})
        self.items_dir = items_dir
        self.total_items: int | None = None  # the planned items, when a preparation says (its stop line)

    # ---------------------------------------------------------------- state
    def _matches(self, info: dict | None) -> bool:
        return bool(info) and info.get("generator") == self.generator and \
            str(info.get("version")) == self.version and info.get("config_hash") == self.config_hash

    def manifest(self) -> dict | None:
        """The manifest (None when there is none). One of this config is checked against its items
        (:func:`datamodules.cache_guard.manifest_problem`): a mismatch raises :class:`DataError`."""
        m = read_manifest(self.root)
        if m is None or not self._matches(m):
            return m
        problem, _ = manifest_problem(self.root, m, stable_hash(m.get("items", [])))
        if problem:
            raise DataError(f"{self.root}: {problem}; run lit3d-data with this run's overrides to repair it")
        watch(self.root, m)
        return m

    def _safe_manifest(self) -> dict | None:
        try:
            return self.manifest()
        except DataError:  # half-written manifests cannot happen (atomic), but hand edits can
            return None

    def is_complete(self) -> bool:
        """True when a manifest of this generator/version/config exists, matches its items and all
        its files are there (and no rebuild of the folder is pending)."""
        if _rebuild_pending(self.root):
            return False
        m = self._safe_manifest()
        return self._matches(m) and all((self.root / it["file"]).is_file() for it in m["items"])

    def path(self, rel: str) -> Path:
        """``root / rel``; a stop point (:func:`lit3d.utils.stops.check_stop`): a preparation asks for
        each item's path before it writes the item, so Ctrl-C or SIGTERM stops it at the next item."""
        check_stop()
        return self.root / rel

    def has(self, rel: str) -> bool:
        """An item file is complete when it exists (it only ever appears through ``os.replace``); a
        stop point like :meth:`path`."""
        check_stop()
        p = self.root / rel
        return p.is_file() and p.stat().st_size > 0

    # ---------------------------------------------------------------- protocol
    @contextlib.contextmanager
    def locked(self) -> Iterator[None]:
        """Hold the preparation lock of ``root`` (``flock`` on ``root/.lock``; blocking, with a log
        line while another process holds it). Released on exit, exceptions included, and by the
        system when the holder dies; re-entrant in one thread. Re-check :meth:`is_complete` inside."""
        key = (str(self.root.resolve()), threading.get_ident())
        with self._held_guard:
            depth = self._held.get(key, 0)
            if depth:
                self._held[key] = depth + 1
        if depth:
            try:
                yield
            finally:
                with self._held_guard:
                    self._held[key] -= 1
            return
        self.root.mkdir(parents=True, exist_ok=True)
        path = self.root / LOCK
        with open(path, "a+") as f:
            flock_waiting(f, path)
            with self._held_guard:
                self._held[key] = 1
            try:
                f.seek(0)
                f.truncate()
                f.write(f"{os.getpid()}\n")  # who holds it, for the waiting processes' log line
                f.flush()
                yield
            finally:
                with self._held_guard:
                    del self._held[key]
                funlock(f)

    def prepare_once(self, write_items: Callable[[CacheBuilder], tuple[list[dict], dict | None]],
                     before: Callable[[], object] | None = None) -> bool:
        """The locked, double-checked preparation of ``root`` that every ``prepare_data()`` runs: nothing
        when the cache is complete; else, holding :meth:`locked` (multirun jobs take turns), check
        again (another process may have finished it meanwhile), then ``before()`` (e.g. removing an
        older layout), :meth:`begin`, ``write_items(self) -> (items, extra)``, :meth:`finish`.
        Returns True when this process prepared the cache. A stop (Ctrl-C or SIGTERM under
        :func:`lit3d.utils.stops.on_signals`) comes out as :class:`~lit3d.utils.stops.StopRequested`
        naming ``root`` and the items on disk; a rerun makes only the missing ones."""
        if self.is_complete():
            return False
        try:
            with self.locked():
                if self.is_complete():  # another process prepared it while this one waited
                    return False
                if before is not None:
                    before()
                self.begin()
                items, extra = write_items(self)
                self.finish(items, extra)
        except StopRequested as stop:
            stop.where, stop.done, stop.total = self.root, self._items_on_disk(), self.total_items
            raise
        return True

    def begin(self) -> None:
        """Start or resume: clean temp files, refuse a folder of another config (or wipe it after
        :func:`request_rebuild`), remove the items a checked manifest names as bad, write the marker."""
        self.root.mkdir(parents=True, exist_ok=True)
        n_tmp = clean_temp_files(self.root)
        if n_tmp:
            log.info("%s: removed %d unfinished temp file(s) of an interrupted preparation", self.root, n_tmp)
        marker_path = self.root / MARKER
        marker = _read_json(marker_path)
        try:
            manifest = read_manifest(self.root)
        except DataError:
            manifest = None  # unreadable: rewritten below
        if _rebuild_pending(self.root):
            log.warning("%s: --rebuild: deleting the prepared items and preparing them again", self.root)
            (self.root / MANIFEST).unlink(missing_ok=True)  # first: a run reading the folder then says why
            shutil.rmtree(self.root / self.items_dir, ignore_errors=True)
            marker = None
        elif manifest is not None and "generator" not in manifest and marker is None:
            log.warning("%s: cached data of an older lit3d layout: preparing it again", self.root)
            shutil.rmtree(self.root / self.items_dir, ignore_errors=True)
        else:
            self._refuse_other_config(manifest, marker)
            if manifest is not None:
                problem, bad = manifest_problem(self.root, manifest, stable_hash(manifest.get("items", [])))
                if problem:
                    log.warning("%s: %s: repairing (%d item(s) made again)", self.root, problem, len(bad))
                for rel in bad:
                    (self.root / rel).unlink(missing_ok=True)
        (self.root / MANIFEST).unlink(missing_ok=True)
        if not self._matches(marker):
            write_json(marker_path, {"generator": self.generator, "version": self.version,
                                     "config_hash": self.config_hash, "config": self.config})

    def _refuse_other_config(self, manifest: dict | None, marker: dict | bool | None) -> None:
        """Raise :class:`DataError` (nothing deleted) when the folder holds data of another config."""
        if marker is False:
            differs = f"{MARKER} is unreadable"
        elif manifest is not None and not self._matches(manifest):
            differs = config_difference(manifest, self.generator, self.version, self.config)
        elif not self._has_items():  # only another config's marker (its preparation made nothing): replaced
            return
        elif marker is not None and not self._matches(marker):
            differs = config_difference(marker, self.generator, self.version, self.config)
        elif manifest is None and marker is None:
            differs = config_difference(None, self.generator, self.version, self.config)
        else:
            return
        raise DataError(f"{self.root}: holds data prepared with another config ({differs or 'config hash'}); "
                        "nothing was deleted: to replace it run lit3d-data with this run's overrides plus --rebuild, "
                        "or set data.data_dir to another folder")

    def _has_items(self) -> bool:
        d = self.root / self.items_dir
        return d.is_dir() and any(p.is_file() for p in d.rglob("*"))

    def _items_on_disk(self) -> int:
        d = self.root / self.items_dir
        return sum(p.is_file() and not p.name.startswith(".") for p in d.rglob("*")) if d.is_dir() else 0

    def finish(self, items: list[dict], extra: dict | None = None) -> dict:
        """Check every item file exists, record its sha256, then write the manifest atomically
        (the marker stays)."""
        missing = [it["file"] for it in items if not self.has(it["file"])]
        if missing:
            raise DataError(f"{self.root}: {len(missing)} item file(s) missing after preparation, e.g. {missing[0]}")
        items = [{**it, "sha256": file_sha256(self.root / it["file"])} for it in items]
        manifest = {
            "generator": self.generator, "version": self.version, "config": self.config,
            "config_hash": self.config_hash, "items": items, "manifest_hash": stable_hash(items),
            "item_bytes": {it["file"]: (self.root / it["file"]).stat().st_size for it in items},
            **(extra or {}),
        }
        write_json(self.root / MANIFEST, manifest)
        _REBUILD["done"].add(str(self.root.resolve()))
        watch(self.root, manifest)
        return manifest


def _read_json(path: Path) -> dict | bool | None:
    """The JSON object in ``path``; None when there is no file, False when it is unreadable."""
    if not path.is_file():
        return None
    try:
        obj = json.loads(path.read_text("utf-8"))
    except (OSError, json.JSONDecodeError):
        return False
    return obj if isinstance(obj, dict) else False


def bytes_on_disk(root: str | os.PathLike, files: Iterable[str]) -> int:
    """Total size of ``files`` (relative to ``root``) plus the manifest."""
    root = Path(root)
    total = sum((root / f).stat().st_size for f in files)
    m = root / MANIFEST
    return total + (m.stat().st_size if m.is_file() else 0)
