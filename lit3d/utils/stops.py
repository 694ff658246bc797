"""Stop points: Ctrl-C (SIGINT) or SIGTERM during a long loop is acted on at the loop's next item.

    with on_signals():        # a command's scope: its handlers for SIGINT and SIGTERM
        for item in items:
            check_stop()      # raises StopRequested once a signal came
            write(item)       # every write is atomic: an item is whole or absent

The first signal is only recorded (:func:`pending`); the next :func:`check_stop` raises
:class:`StopRequested`. A second signal (of either kind) raises it at once, where the program is
(the atomic writers remove their temp file, so nothing half-written is kept), except inside
:func:`shielded` (renames that must finish together) and once a stop is under way (a third
Ctrl-C does not break off the clean-up of the second). Where the program cannot act on it (inside a
long native call, or a stop whose exit hangs), the commands' watcher ends the process within 2 s
of the second signal (:mod:`lit3d.utils.forced_exit`). Outside :func:`on_signals` nothing is
recorded and :func:`check_stop` does nothing. The handlers are installed also where SIGINT came
ignored from the parent (a background job of a non-interactive shell), as ``lit3d-train``'s training
handler is. Used by data preparation (:class:`datamodules.cache.CacheBuilder`), by ``lit3d-data``,
``lit3d-train`` (while it prepares data) and ``lit3d-eval`` (:mod:`lit3d.cli.stops`).
"""
from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

from lit3d.utils.forced_exit import ignore

LABELS = {"SIGINT": "SIGINT (Ctrl-C)", "SIGTERM": "SIGTERM"}
_state: dict = {"pending": None, "armed": False, "shielded": 0, "raised": False, "early": None}


class StopRequested(BaseException):
    """A stop asked for by a signal (``signame``: ``"SIGINT"`` or ``"SIGTERM"``), raised at a stop point.

    A ``BaseException`` like ``KeyboardInterrupt``, so no ``except Exception`` of a loop swallows it,
    but not a ``KeyboardInterrupt``: Lightning ends a run on one of those with exit 1 and no word of
    what was kept. ``where``, ``done``, ``total``: the folder being prepared and how many of its
    items are on disk (set by :meth:`datamodules.cache.CacheBuilder.prepare_once`; None when unknown).
    """

    def __init__(self, signame: str = "SIGINT"):
        super().__init__(signame)
        self.signame = signame
        self.where: Path | None = None
        self.done: int | None = None
        self.total: int | None = None

    @property
    def label(self) -> str:
        """``"SIGINT (Ctrl-C)"`` or ``"SIGTERM"``."""
        return LABELS.get(self.signame, self.signame)


@contextlib.contextmanager
def start_up() -> Iterator[None]:
    """A command's start (before any :func:`on_signals` stage): Ctrl-C raises ``KeyboardInterrupt`` as usual, and
    is also remembered, so that one lost on the way (raised inside a finaliser or a callback that a library
    runs, where Python prints "Exception ignored" and goes on) still stops the command when its first stage
    begins: :func:`on_signals` raises ``KeyboardInterrupt`` at its start. Outside the main thread: as is."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def remember(signum, frame) -> None:
        _state["early"] = signal.Signals(signum).name
        signal.default_int_handler(signum, frame)

    before = signal.signal(signal.SIGINT, remember)
    try:
        yield
    finally:
        _state["early"] = None
        if signal.getsignal(signal.SIGINT) is remember:  # not when a stage ignores signals on the way out
            signal.signal(signal.SIGINT, before if before is not None else signal.SIG_DFL)


def pending() -> str | None:
    """The name of the signal received inside :func:`on_signals` and not yet acted on, or None."""
    return _state["pending"]


def check_stop() -> None:
    """A stop point: raise :class:`StopRequested` when a signal came (inside :func:`on_signals`)."""
    if _state["pending"] is not None:
        _state["raised"] = True
        raise StopRequested(_state["pending"])


@contextlib.contextmanager
def shielded() -> Iterator[None]:
    """Inside: a second signal is recorded too, never raised where the program is (for renames that
    must all happen); :func:`check_stop` after the block acts on it."""
    _state["shielded"] += 1
    try:
        yield
    finally:
        _state["shielded"] -= 1


@contextlib.contextmanager
def on_signals(notify: Callable[[str], object] | None = None, ignore_after_stop: bool = False) -> Iterator[None]:
    """Handle SIGINT and SIGTERM as stop requests inside the block (see the module doc); the earlier
    handlers are put back after it, and a pending stop is forgotten. ``notify(signame)`` is called on
    the first signal. ``ignore_after_stop``: when the block ends in :class:`StopRequested`, ignore the
    two signals from then on instead (a command on its way out: another Ctrl-C must not break off its
    exit with a traceback; :func:`lit3d.utils.forced_exit.ignore`, which the watcher still sees: a
    second signal ends an exit that hangs). Outside the main thread (where Python delivers signals) the block runs as is."""
    if threading.current_thread() is not threading.main_thread() or _state["armed"]:
        yield
        return
    if _state["early"]:  # a Ctrl-C of the command's start that something swallowed (:func:`start_up`)
        raise KeyboardInterrupt

    def on_signal(signum, _frame) -> None:
        name = signal.Signals(signum).name
        if _state["pending"] is None:
            _state["pending"] = name
            if notify is not None:
                notify(name)
        elif not _state["shielded"] and not _state["raised"]:  # else the stop is already under way
            _state["raised"] = True
            raise StopRequested(_state["pending"])

    _state.update(pending=None, armed=True, raised=False)  # first: a signal right after the handlers go in is kept
    previous = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    stopped = False
    try:
        yield
    except StopRequested:
        stopped = ignore_after_stop
        raise
    finally:
        _state.update(pending=None, armed=False, raised=False)
        for s, handler in previous.items():
            signal.signal(s, ignore if stopped else signal.SIG_DFL if handler is None else handler)
