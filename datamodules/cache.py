"""Generic on-disk cache pieces shared by every lit3d DataModule.

- :class:`DataError`: a bad input file or setting, one message naming the file/setting.
- :func:`stable_hash` / :func:`stable_seed`: hashes and RNG seeds that do not depend
  on Python's per-process ``hash()`` salt.
- :func:`atomic_save_npz`: arrays -> ``.npz`` through a temp file + ``os.replace``.
- :class:`CacheBuilder`: the preparation protocol. A ``prepare.json`` marker (generator,
  version, config hash of the item files in the folder) is written first and kept,
  items are written atomically one by one, ``manifest.json`` is written last
  (atomically). Re-running skips items already on disk (also when the manifest was
  deleted); a marker or manifest from another config/version, or item files of
  unknown origin, wipe the stale items first, so a cache never mixes two configs.
  :meth:`CacheBuilder.locked` holds an inter-process lock (``flock`` on ``<root>/.lock``)
  around a preparation: processes preparing one folder at once (the jobs of a multirun)
  take turns, and the later ones find the cache complete.

Manifest layout (``manifest.json``)::

    {"generator": str, "version": str, "config": {...}, "config_hash": sha256,
     "items": [{"file": "items/...npz", "sha256": of the file's bytes, "split": ..., ...}, ...],
     "manifest_hash": sha256 of the canonical JSON of "items", ...extra}

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
import tempfile
import threading
import zlib
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from lit3d.utils.io import TMP_SUFFIX, atomic_write_bytes, file_mode, file_sha256, remove_temp_files, write_json

log = logging.getLogger("lit3d.data")

MANIFEST = "manifest.json"
MARKER = "prepare.json"
LOCK = ".lock"

__all__ = [
    "LOCK", "MANIFEST", "MARKER", "CacheBuilder", "DataError", "atomic_save_npz", "atomic_write_bytes",
    "clean_temp_files", "file_sha256", "read_manifest", "stable_hash", "stable_int_seed", "stable_seed", "write_json",
]


class DataError(ValueError):
    """A bad data file or data setting; the message names the file (or setting) and the problem."""


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
    """Save ``arrays`` as ``path`` (.npz) via a temp file in the same folder + ``os.replace``.

    An interrupted write leaves only a ``.<name>.*.tmp`` file, which
    :func:`clean_temp_files` removes; ``path`` is either absent or complete.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=TMP_SUFFIX)
    try:
        os.fchmod(fd, file_mode())  # the umask's mode (0644 under 022), not mkstemp's 0600
        with os.fdopen(fd, "wb") as f:
            (np.savez_compressed if compress else np.savez)(f, **arrays)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


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

    Usage::

        b = CacheBuilder(root, generator="completion_synth", version="1", config=cfg)
        if not b.is_complete():
            with b.locked():              # one process at a time prepares ``root``
                if not b.is_complete():   # another one may have finished it meanwhile
                    b.begin()
                    for item in items:
                        if not b.has(item["file"]):
                            atomic_save_npz(b.path(item["file"]), ...)
                    b.finish(items, extra={...})
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

    # ---------------------------------------------------------------- state
    def _matches(self, info: dict | None) -> bool:
        return bool(info) and info.get("generator") == self.generator and \
            str(info.get("version")) == self.version and info.get("config_hash") == self.config_hash

    def manifest(self) -> dict | None:
        return read_manifest(self.root)

    def _safe_manifest(self) -> dict | None:
        try:
            return self.manifest()
        except DataError:  # half-written manifests cannot happen (atomic), but hand edits can
            return None

    def is_complete(self) -> bool:
        """True when a manifest of this generator/version/config exists and all its files are there."""
        m = self._safe_manifest()
        return self._matches(m) and all((self.root / it["file"]).is_file() for it in m["items"])

    def path(self, rel: str) -> Path:
        return self.root / rel

    def has(self, rel: str) -> bool:
        """An item file is complete when it exists (it only ever appears through ``os.replace``)."""
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
            _flock_waiting(f, path)
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
                _funlock(f)

    def begin(self) -> None:
        """Start or resume: clean temp files, wipe items of another config, write the marker."""
        self.root.mkdir(parents=True, exist_ok=True)
        n_tmp = clean_temp_files(self.root)
        if n_tmp:
            log.info("%s: removed %d unfinished temp file(s) of an interrupted preparation", self.root, n_tmp)
        marker_path = self.root / MARKER
        marker = None
        if marker_path.is_file():
            try:
                marker = json.loads(marker_path.read_text("utf-8"))
            except (OSError, json.JSONDecodeError):
                marker = None
        manifest = self._safe_manifest()
        stale = (manifest is not None and not self._matches(manifest)) or \
                (marker is not None and not self._matches(marker)) or \
                (marker_path.is_file() and marker is None)
        if manifest is None and marker is None and (self.root / self.items_dir).exists():
            stale = True  # items of unknown origin
        if stale:
            log.warning("%s: cached data is from another config or generator version: regenerating", self.root)
            shutil.rmtree(self.root / self.items_dir, ignore_errors=True)
        (self.root / MANIFEST).unlink(missing_ok=True)
        if stale or not self._matches(marker):
            write_json(marker_path, {"generator": self.generator, "version": self.version,
                                     "config_hash": self.config_hash, "config": self.config})

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
            **(extra or {}),
        }
        write_json(self.root / MANIFEST, manifest)
        return manifest


def _flock_waiting(f, path: Path) -> None:
    """Exclusive ``flock`` on the open file ``f``; logs once when it has to wait. Without
    ``fcntl`` (Windows) or on a file system that refuses locks: a warning, no lock."""
    try:
        import fcntl  # noqa: PLC0415
    except ImportError:  # pragma: no cover - not POSIX
        log.warning("%s: no fcntl here: preparing without the inter-process lock", path)
        return
    try:
        fcntl.flock(f.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        return
    except BlockingIOError:
        f.seek(0)
        holder = f.read().strip() or "?"
        log.info("%s: another process (pid %s) is preparing this data; waiting for it", path.parent, holder)
    except OSError as exc:  # e.g. ENOLCK on some network file systems
        log.warning("%s: cannot lock (%s): preparing without the inter-process lock", path, exc)
        return
    fcntl.flock(f.fileno(), fcntl.LOCK_EX)
    log.info("%s: the other preparation is done; going on", path.parent)


def _funlock(f) -> None:
    """Forget the holder's pid, then release (closing the file would release it too)."""
    try:
        f.truncate(0)
        f.flush()
        import fcntl  # noqa: PLC0415

        fcntl.flock(f.fileno(), fcntl.LOCK_UN)
    except (ImportError, OSError):
        pass


def bytes_on_disk(root: str | os.PathLike, files: Iterable[str]) -> int:
    """Total size of ``files`` (relative to ``root``) plus the manifest."""
    root = Path(root)
    total = sum((root / f).stat().st_size for f in files)
    m = root / MANIFEST
    return total + (m.stat().st_size if m.is_file() else 0)
