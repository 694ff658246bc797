"""Small file helpers: atomic writes, JSON that never leaves half a file behind, and the one
output writer of the command-line tools (:func:`check_output_dir`, :func:`unique_names`,
:func:`write_file_set`, :func:`repair_sets`).

Every file written here gets the mode an ordinary ``open()`` would give under the user's umask
(``0644`` under umask ``022``), not the ``0600`` of :func:`tempfile.mkstemp`. File-system
problems of outputs (exists as a file or folder, read-only, no permission, no space) are raised
as :class:`OutputError`: one line ``<path>: <problem>``, a user error (exit 2) in every entry
point.
"""
from __future__ import annotations

import contextlib
import errno
import glob
import hashlib
import json
import os
import shutil
import tempfile
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any, BinaryIO

from lit3d.utils.errors import Lit3dError
from lit3d.utils.forced_exit import on_forced_exit
from lit3d.utils.kill_points import kill_point
from lit3d.utils.temp_names import TMP_SUFFIX, temp_prefix, writer, writer_gone

STAGE_PREFIX = ".evaluation."  # an evaluation's staging folder inside its run dir (lit3d.cli.evaluation.staged_outputs)


class OutputError(Lit3dError, ValueError):
    """An output path that cannot be written (or would replace an input): ``<path>: <problem>``."""


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def file_mode() -> int:
    """The mode ``open(path, "w")`` gives a new file under the current umask (``0o644`` under 022)."""
    return 0o666 & ~_umask()


def _problem(exc: OSError) -> str:
    """A short phrase for an OSError of an output path."""
    known = {errno.EROFS: "read-only file system", errno.EACCES: "permission denied",
             errno.EPERM: "permission denied", errno.ENOSPC: "no space left on the device",
             errno.EDQUOT: "disk quota exceeded", errno.EISDIR: "exists and is a folder",
             errno.ENOTDIR: "a parent of it is a file, not a folder", errno.EEXIST: "exists"}
    return known.get(exc.errno, exc.strerror or type(exc).__name__)


def output_error(path: str | os.PathLike, exc: OSError) -> OutputError:
    """``OutputError("<path>: <problem>")`` for an OSError met while writing ``path``."""
    return OutputError(f"{path}: cannot write here ({_problem(exc)})")


@contextlib.contextmanager
def atomic_file(path: str | os.PathLike) -> Iterator[BinaryIO]:
    """An open binary file whose bytes replace ``path`` when the block ends without an error: a temp
    file in the same folder (the umask's mode, see :func:`file_mode`) + ``os.replace``; on any error
    the temp file is removed and ``path`` is left as it was. An OSError that names no file or only the
    temp file (``write()`` on a full disk names none) is raised again naming ``path``, so the entry
    points can say which file could not be written (``<path>: cannot write here (no space ...)``).
    A forced exit (:mod:`lit3d.utils.forced_exit`) removes the temp file first."""
    path, tmp = Path(path), None

    def forced() -> str | None:
        if tmp is None or not os.path.lexists(tmp):
            return None
        Path(tmp).unlink(missing_ok=True)
        return f"{path}: not written (its temp file was removed)"

    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with on_forced_exit(forced):
            fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=temp_prefix(path.name), suffix=TMP_SUFFIX)
            with os.fdopen(fd, "wb") as f:
                os.fchmod(f.fileno(), file_mode())
                yield f
            kill_point(f"write:{path.name}")
            os.replace(tmp, path)
            tmp = None
        remove_left_temps(path)
    except BaseException as exc:
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)
        if isinstance(exc, OSError) and exc.errno is not None and exc.filename in (None, tmp):
            raise OSError(exc.errno, exc.strerror or os.strerror(exc.errno), str(path)) from exc
        raise


def remove_left_temps(path: str | os.PathLike) -> list[Path]:
    """Remove the temp files of ``path`` (``.<name>.<pid>-<host>.*.tmp`` beside it) whose writer was
    killed (:func:`lit3d.utils.temp_names.writer_gone`: this host, a pid that no longer runs); the
    temps of running writers and of other hosts stay. Returns the removed paths."""
    path, removed = Path(path), []
    with contextlib.suppress(OSError):
        for p in path.parent.glob(f".{glob.escape(path.name)}.*{TMP_SUFFIX}"):
            w = writer(p.name)
            if w is not None and w.name == path.name and writer_gone(p.name, with_host=True) and p.is_file():
                p.unlink(missing_ok=True)
                removed.append(p)
    return removed


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` through a temp file in the same folder + ``os.replace``
    (:func:`atomic_file`: the umask's mode; an OSError names ``path``)."""
    with atomic_file(path) as f:
        f.write(data)
    return Path(path)


def remove_temp_files(root: str | os.PathLike) -> int:
    """Remove leftover temp files (``.*.tmp``) of interrupted atomic writes under ``root``; returns how many."""
    root = Path(root)
    if not root.exists():
        return 0
    n = 0
    for p in root.rglob(f".*{TMP_SUFFIX}"):
        if p.is_file():
            p.unlink(missing_ok=True)
            n += 1
    return n


def file_sha256(path: str | os.PathLike, chunk: int = 1 << 20) -> str:
    """sha256 hex digest of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(chunk):
            h.update(block)
    return h.hexdigest()


def atomic_write_text(path: str | os.PathLike, text: str) -> Path:
    """Atomic UTF-8 text write (see :func:`atomic_write_bytes`)."""
    return atomic_write_bytes(path, text.encode("utf-8"))


def write_json(path: str | os.PathLike, obj: Any) -> Path:
    """Atomic, sorted, indented JSON; NaN/inf are written as null."""
    return atomic_write_text(path, json.dumps(_finite(obj), indent=2, sort_keys=True) + "\n")


def _finite(obj: Any) -> Any:
    if isinstance(obj, float) and (obj != obj or obj in (float("inf"), float("-inf"))):
        return None
    if isinstance(obj, dict):
        return {str(k): _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    return obj


# ------------------------------------------------------------------ the output writer of the CLIs
def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.resolve() == b.resolve() or (a.exists() and b.exists() and os.path.samefile(a, b))
    except OSError:
        return False


def check_output_dir(path: str | os.PathLike, option: str = "--out") -> Path:
    """Make sure ``path`` is (or can be made) a writable folder, before any expensive work.

    Creates it (and its parents) when missing; probes it with a temp file that is removed again.
    Raises :class:`OutputError` (``<path>: <problem>``): an existing file, a parent that is a
    file, a read-only file system, no permission.
    """
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise OutputError(f"{p}: {option} is an existing file, not a folder")
    for parent in p.parents:  # the nearest existing ancestor must be a folder
        if parent.exists():
            if not parent.is_dir():
                raise OutputError(f"{p}: {option} lies under {parent}, which is a file, not a folder")
            break
    try:
        p.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(dir=p, prefix=temp_prefix("lit3d-probe"), suffix=TMP_SUFFIX)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise OutputError(f"{p}: {option} is not writable ({_problem(exc)})") from None
    return p


def check_writable(path: str | os.PathLike, option: str, need_write: bool = True) -> Path:
    """Like :func:`check_output_dir` but creates nothing: ``path`` must not be (or lie under) a
    file, and, when ``need_write``, its nearest existing folder must be writable (a read-only
    file system or a folder without write permission is refused). Raises :class:`OutputError`."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise OutputError(f"{p}: {option} is an existing file, not a folder")
    anc = next((q for q in p.parents if q.exists()), None) if not p.exists() else p
    if anc is not None and not anc.is_dir():
        raise OutputError(f"{p}: {option} lies under {anc}, which is a file, not a folder")
    if need_write and anc is not None:
        try:  # a real probe (a temp file, removed again): access() ignores sysfs and some mounts
            fd, probe = tempfile.mkstemp(dir=anc, prefix=temp_prefix("lit3d-probe"), suffix=TMP_SUFFIX)
            os.close(fd)
            os.unlink(probe)
        except OSError as exc:
            raise OutputError(f"{p}: {option} is not writable ({_problem(exc)}"
                              f"{'' if anc == p else f' at {anc}'})") from None
    return p


def unique_names(inputs: Sequence[str | os.PathLike]) -> tuple[list[str], list[str]]:
    """Output base names for ``inputs``, unique per input: the stem, or, where stems collide,
    the stem with the extension (``a_cow.png`` -> ``a_cow_png``), then with the parent folder
    (``x/scan.png`` -> ``x_scan_png``), then numbered. Returns ``(names, notes)``, a note per
    renamed input saying so."""
    paths = [Path(p) for p in inputs]
    names = [p.stem for p in paths]

    def colliding(ns: list[str]) -> set[int]:
        seen: dict[str, list[int]] = {}
        for i, n in enumerate(ns):
            seen.setdefault(n.lower(), []).append(i)  # case-insensitive file systems too
        return {i for idx in seen.values() if len(idx) > 1 for i in idx}

    for rule in (lambda p: f"{p.stem}_{p.suffix.lstrip('.')}" if p.suffix else p.stem,
                 lambda p: f"{p.parent.name}_{p.stem}_{p.suffix.lstrip('.')}".strip("_")):
        clash = colliding(names)
        if not clash:
            break
        for i in clash:
            names[i] = rule(paths[i])
    clash = colliding(names)
    used = {n.lower() for i, n in enumerate(names) if i not in clash}
    for i in sorted(clash):
        k, base = 2, names[i]
        while names[i].lower() in used:
            names[i] = f"{base}_{k}"
            k += 1
        used.add(names[i].lower())
    notes = [f"{p}: output name '{n}' (the stem '{p.stem}' is shared by another input)"
             for p, n in zip(paths, names) if n != p.stem]
    return names, notes


def check_targets(targets: Iterable[str | os.PathLike], protected: Iterable[str | os.PathLike] = (),
                  hint: str = "choose another output folder") -> None:
    """Raise :class:`OutputError` when an output path is, or would replace, a ``protected`` file
    (an input: the same path, a link to it or a hard link of it), or exists as a folder; all before
    anything is written. ``hint``: what the line tells the user to do instead."""
    prot = [Path(p) for p in protected if p]
    for t in map(Path, targets):
        for q in prot:
            if _same_file(t, q):
                raise OutputError(f"{t}: the output would replace the input {q} ({hint})")
        if t.is_dir():
            raise OutputError(f"{t}: an output file of this name exists as a folder")


SET_JOURNAL = ".set.json"  # in a staging folder: the set is committed (every file staged)


def write_file_set(out_dir: str | os.PathLike, files: dict[str, bytes],
                   protected: Iterable[str | os.PathLike] = ()) -> list[Path]:
    """Write ``files`` (file name -> bytes) into ``out_dir`` as one set.

    Every file is written into a staging folder ``out_dir/.<first name>.<pid>.<random>.tmp/``;
    when all are there a journal (``.set.json``, the names in order) is written into it, and only
    then are the files renamed into place (in the given order: put the summary last). A failure
    before the journal leaves the earlier set untouched; Ctrl-C during the renames finishes them
    (the new set is whole); any other failure during them removes the whole set (never a mix of
    two sets). A SIGKILL during the renames leaves the journal: :func:`repair_sets` (run by the
    next ``lit3d-reconstruct`` on the folder) finishes the renames; a forced exit
    (:mod:`lit3d.utils.forced_exit`) finishes a committed set and removes one still being staged. Files
    get the umask's mode.
    ``protected``: input files the set must not replace (:func:`check_targets`). Raises
    :class:`OutputError`.
    """
    out = Path(out_dir)
    names = list(files)
    if SET_JOURNAL in names:
        raise ValueError(f"{out / SET_JOURNAL}: reserved name")
    check_targets([out / name for name in names], protected)
    try:
        out.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(dir=out, prefix=temp_prefix(next(iter(files), "set")), suffix=TMP_SUFFIX))
    except OSError as exc:
        raise output_error(out, exc) from None
    committed = False

    def forced() -> str | None:
        if not tmp.is_dir():
            return None
        if committed:  # whole: finish the renames (the main thread may be doing the same: either one wins)
            for name in names:
                with contextlib.suppress(OSError):
                    os.replace(tmp / name, out / name)
            shutil.rmtree(tmp, ignore_errors=True)
            return f"{out}: the set {', '.join(names)} was finished"
        shutil.rmtree(tmp, ignore_errors=True)
        return f"{out}: the set {', '.join(names)} was not written (its staging folder was removed)"

    with on_forced_exit(forced):  # registered first: its clean-up runs before the journal's
        try:
            for name, data in files.items():
                try:
                    with open(tmp / name, "wb") as f:  # an ordinary open(): the umask's mode
                        f.write(data)
                except OSError as exc:
                    raise output_error(out / name, exc) from None
            try:
                atomic_write_bytes(tmp / SET_JOURNAL, json.dumps({"files": names, "pid": os.getpid()}).encode("utf-8"))
            except OSError as exc:
                raise output_error(out / names[0], exc) from None
            committed = True
            kill_point("file-set:committed")
            _move_set(tmp, out, names)
        except KeyboardInterrupt:
            if committed:  # the staged set is whole: finish it rather than leave a mix
                _settle(tmp, out, names)
            raise
        except BaseException:
            if committed:
                _remove_set(out, names)
            raise
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
    return [out / name for name in names]


def _move_set(staging: Path, out: Path, names: Sequence[str]) -> None:
    """Rename the staged files that are still there into ``out`` (in order), then drop the journal."""
    for name in names:
        src = staging / name
        if src.exists():
            try:
                os.replace(src, out / name)
            except OSError as exc:
                raise output_error(out / name, exc) from None
    (staging / SET_JOURNAL).unlink(missing_ok=True)


def _settle(staging: Path, out: Path, names: Sequence[str]) -> None:
    try:
        _move_set(staging, out, names)
    except OutputError:
        _remove_set(out, names)


def _remove_set(out: Path, names: Sequence[str]) -> None:
    for name in names:
        (out / name).unlink(missing_ok=True)


def repair_sets(out_dir: str | os.PathLike, idle: bool = False) -> list[str]:
    """Settle what writers that are gone left in ``out_dir``: a staging folder with its journal (the
    process died during the renames) has its renames finished; one without (it died while
    staging) is removed. Staging folders of running processes (and of other hosts) are left alone.
    ``idle``: no process writes into ``out_dir`` (its run dir lock is held by this process, or its
    holder is gone): every staging folder and temp file there is a leftover, those of other hosts too.
    Temp files (``.<name>.<pid>-<host>.<random>.tmp``) of writers that are gone are removed as well.
    Returns one note per folder or file handled."""
    out, notes = Path(out_dir), []
    if not out.is_dir():
        return notes
    for entry in sorted(out.glob(f".*{TMP_SUFFIX}")):
        w = writer(entry.name)
        if not idle and w is not None and not writer_gone(entry.name) and w.pid != os.getpid():
            continue  # a running writer's, or another host's
        if entry.is_file():  # only the names this project writes (with the writer's pid)
            if w is not None and (idle or writer_gone(entry.name, with_host=True)):
                entry.unlink(missing_ok=True)
                notes.append(f"{entry}: removed the temp file of an interrupted write")
            continue
        if not entry.is_dir():
            continue
        try:
            journal = json.loads((entry / SET_JOURNAL).read_text("utf-8"))
        except (OSError, ValueError):
            journal = None
        if isinstance(journal, dict) and isinstance(journal.get("files"), list):
            _settle(entry, out, [str(n) for n in journal["files"]])
            notes.append(f"{out}: finished the set {', '.join(map(str, journal['files']))} "
                         "that an interrupted run had left half renamed")
        else:
            notes.append(f"{entry}: removed the staging folder of an interrupted run")
        shutil.rmtree(entry, ignore_errors=True)
    return notes
