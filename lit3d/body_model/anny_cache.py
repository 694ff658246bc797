"""The Anny body model's cache: where anny keeps it, whether the model's file is built, and what its
first build says, and leaves when it is stopped.

anny builds its model data on its first start and keeps it in ``anny.paths.get_anny_cache_path()``
(``$ANNY_CACHE_DIR``, default ``~/.cache/anny``) as ``v<data version>/<builder>_<hash>.safetensors``:
three files of about 790 MB together (:data:`PARTS`). ``anny.Anny()`` loads the last one,
:func:`model_file`, when it exists, and otherwise builds what is missing: about 2.5 min on 2 idle
cores (:data:`BUILD_S`), most of it in ``load_data`` (:data:`PARTS`), with no word of its own on the
console (anny logs at INFO, which the argparse commands do not show).

anny writes each file in place (``safetensors.torch.save_file``, no temp file and rename): a process
killed while it writes one leaves a truncated file, which the next start takes for a complete one
(anny only checks that the file exists) and then fails to read. Hence:

- :func:`first_build` around ``anny.Anny()``: silent when :func:`model_file` is there and whole; else
  one line saying what is built, where, how big and how long it usually takes, then a heartbeat every
  10 s (:func:`lit3d.utils.progress.ticking`); a stop during the build (Ctrl-C, SIGTERM: the first
  one, the build is not worth waiting for) ends the command within 2 s
  (:func:`lit3d.utils.forced_exit.native_step`) and removes the file anny was writing;
- :func:`remove_truncated`, run by :func:`first_build` first: a truncated cache file that an
  interrupted build left (written more than :data:`STALE_S` ago) is removed, so anny builds it again
  instead of failing to read it.
"""
from __future__ import annotations

import contextlib
import json
import os
import struct
import time
from collections.abc import Callable, Iterator
from pathlib import Path

from lit3d.utils.forced_exit import native_step
from lit3d.utils.progress import duration, say_or_log, ticking

BUILD_S = 150.0  # a whole first build on 2 idle cores (docs/data_formats.md)
# anny's builders in the order they finish: (size in MiB, share of a whole build's time), from anny's own
# log times of one first build (102 s in all, nice 19 on 2 busy cores): load_data 89 s, build_model_data
# 2 s, the compacting 10 s
PARTS: dict[str, tuple[int, float]] = {
    "load_data": (535, 0.88),
    "build_model_data": (206, 0.02),
    "build_compact_model_data": (49, 0.10),
}
MODEL_BUILDER = "build_compact_model_data"  # the file anny.Anny() loads
STALE_S = 60.0  # a truncated file not written to for this long is a leftover, not a file being written
WHAT = "building the Anny body model's cache"


def cache_dir() -> Path:
    """anny's cache folder (``$ANNY_CACHE_DIR`` as anny read it at import, default ``~/.cache/anny``)."""
    from anny.paths import get_anny_cache_path

    return Path(get_anny_cache_path())


def model_file() -> Path | None:
    """The file ``anny.Anny()`` (its defaults, as :class:`~lit3d.body_model.bodies.BodyModel` calls it)
    loads from the cache, named as anny's ``cache_builder`` names it; None where this anny names its
    files otherwise (the build then goes without the lines of :func:`first_build`)."""
    try:
        import hashlib
        import inspect

        import anny
        from anny.models import build_compact_model_data
        from anny.models.model_data import CURRENT_DATA_VERSION, RigConfig, TopologyConfig, _get_builder_metadata

        defaults = {k: p.default for k, p in inspect.signature(anny.Anny.__init__).parameters.items()
                    if p.default is not inspect.Parameter.empty}
        if defaults.get("phenotype_blendshapes") != "compact":
            return None
        kwargs = {"rig": RigConfig.from_string(defaults["rig"]), "topology": TopologyConfig.from_string(defaults["topology"]),
                  "local_changes": defaults["local_changes"], "facial_actions": defaults["facial_actions"],
                  "phenotypes": defaults["phenotypes"], "rank": None}
        builder = inspect.unwrap(build_compact_model_data)
        meta = _get_builder_metadata(builder, **kwargs)
        digest = hashlib.sha256(json.dumps(meta, sort_keys=True).encode()).hexdigest()[:32]
        return cache_dir() / f"v{CURRENT_DATA_VERSION}" / f"{builder.__name__}_{digest}.safetensors"
    except Exception:  # another anny: its internals moved
        return None


def is_whole(path: Path) -> bool:
    """``path`` is a whole safetensors file: its size is the 8-byte header length, the JSON header
    and the end of its last tensor's data (a file cut short while written is not)."""
    try:
        with open(path, "rb") as f:
            head = f.read(8)
            if len(head) < 8:
                return False
            (n,) = struct.unpack("<Q", head)
            if n > 100_000_000:
                return False
            header = json.loads(f.read(n))
        ends = [int(v["data_offsets"][1]) for k, v in header.items() if k != "__metadata__"]
        return os.path.getsize(path) == 8 + n + max(ends, default=0)
    except (OSError, ValueError, KeyError, TypeError, IndexError):
        return False


def remove_truncated(folder: Path, stale_s: float = STALE_S, before: set[str] | None = None) -> list[Path]:
    """Remove the ``*.safetensors`` in ``folder`` that are not whole (:func:`is_whole`) and were last
    written more than ``stale_s`` seconds ago (0: any; a file being written now stays), or, with
    ``before``, only those whose names are not in it (this process's own). Returns the removed files."""
    removed = []
    with contextlib.suppress(OSError):
        for p in sorted(folder.glob("*.safetensors")):
            if before is not None and p.name in before:
                continue
            with contextlib.suppress(OSError):
                if time.time() - p.stat().st_mtime >= stale_s and not is_whole(p):
                    p.unlink()
                    removed.append(p)
    return removed


def _left(folder: Path) -> tuple[int, float]:
    """(MiB, seconds) still to build: the :data:`PARTS` with no whole file in ``folder``."""
    mib, share = 0, 0.0
    for builder, (size, part) in PARTS.items():
        if not any(is_whole(p) for p in folder.glob(f"{builder}_*.safetensors")):
            mib, share = mib + size, share + part
    return mib, BUILD_S * share


def _shown(path: Path) -> str:
    home = Path.home()
    return f"~/{path.relative_to(home)}" if path.is_relative_to(home) else str(path)


def start_line(where: Path, mib: int, seconds: float) -> str:
    """The line before a first build (``where``: the cache folder)."""
    return (f"{WHAT} in {_shown(where)} (about {mib} MB; about {duration(seconds)} on 2 idle cores, once; "
            "Ctrl-C stops it, and the next start builds it again)")


@contextlib.contextmanager
def first_build(emit: Callable[[str], object] | None = None, every_s: float | None = None) -> Iterator[None]:
    """Around ``anny.Anny()``: see the module doc. ``emit``: where the lines go (default
    :func:`lit3d.utils.progress.say_or_log`: the lit3d log of the Hydra commands, stderr of the others);
    ``every_s``: the heartbeat's interval (default 10 s)."""
    emit = emit or say_or_log
    target = model_file()
    if target is None:
        yield
        return
    folder = target.parent
    for p in remove_truncated(folder):
        emit(f"removed {p}: a truncated file of the Anny cache that an interrupted first start left "
             "(anny cannot read it); it is built again")
    if is_whole(target):
        yield
        return
    before: set[str] = set()
    with contextlib.suppress(OSError):
        before = {p.name for p in folder.glob("*.safetensors")}
    mib, seconds = _left(folder)
    emit(start_line(cache_dir(), mib, seconds))

    def cleanup() -> str | None:
        gone = remove_truncated(folder, stale_s=0, before=before)
        return f"removed the part-written {', '.join(p.name for p in gone)} from {folder} (the next start builds " \
               "it again)" if gone else f"the Anny cache in {folder} is not complete (the next start goes on building it)"

    try:
        with native_step(f"while {WHAT}", cleanup), ticking(WHAT, seconds, emit, every_s):
            yield
    except BaseException:
        cleanup()
        raise
