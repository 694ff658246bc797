"""A second Ctrl-C (or SIGTERM) ends a command within 2 s, whatever the program is doing.

The first SIGINT or SIGTERM asks for a clean stop (:mod:`lit3d.utils.stops`: at the next item, after the
current batch, with a resumable state and one line). But Python runs signal handlers in the main thread
between bytecodes only: inside one long native call (a torch op, a file read, the Anny cache build) it acts
on no signal until the call returns; ``lit3d-reconstruct --body`` stopped twice by SIGTERM during the
first Anny cache build ended 44-65 s later. Inside :func:`watching` (the scope of every lit3d command:
:func:`lit3d.cli.common.cli_main`, :func:`lit3d.cli.about.run_argparse_cli`), a watcher thread sees
each SIGINT and SIGTERM as it arrives (``signal.set_wakeup_fd``: the C-level handler writes the signal's
number to a pipe, whatever the main thread is doing), and

- on the second one (of either kind, also one that the clean stop "ignores" on its way out), or on the
  first one inside :func:`native_step` (work that is not worth waiting for and that the program cannot
  break off by itself, such as the Anny cache build),
- gives the program's own stop path :data:`GRACE_S` to end the process, then
- calls the clean-ups registered with :func:`on_forced_exit` (the temp file of an atomic write, the
  staging folder of a file set, the part-built cache of a native step: :mod:`lit3d.utils.io`,
  :mod:`lit3d.body_model.anny_cache`), writes one line (``error: stopped by a second SIGINT (Ctrl-C);
  ended at once: ...``; nothing more where the command had already said its last line, :func:`said`)
  and ends the process with ``os._exit``: status 130 for SIGINT, 143 for SIGTERM (128 + the signal).

``os._exit`` runs no ``finally`` and no ``atexit``: what a clean-up does not remove stays, as after
SIGKILL, and the next run clears it (:func:`lit3d.utils.io.repair_sets`, :mod:`lit3d.cli.run_leftovers`).
Forked children (DataLoader workers) turn the watching off, so their own Ctrl-C is not counted as the
parent's second one. A forced exit that is due when the scope ends happens then (the command's own stop
line said, or not), not after Python's own end, which takes seconds once torch is loaded; none is ever
due in a process that no signal reached. Outside
:func:`watching` (library use, the tests' own process) nothing changes.
"""
from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator

GRACE_S = 0.75  # after the signal that forces the exit: the program's own stop path may still end it first
LABELS = {int(signal.SIGINT): "SIGINT (Ctrl-C)", int(signal.SIGTERM): "SIGTERM"}

_lock = threading.Lock()
# pipe: (read fd, write fd) while watching; generation: bumped when a scope begins, and when one ends with
# no forced exit due (a pending forced exit of another generation does nothing); count, last: the
# signals seen in this scope; forcing, due: a forced exit is due, its (signal, native step); exiting: one
# thread is ending the process; steps: the native steps under way,
# innermost last; cleanups: token -> clean-up; said: the exit status of a command that has said its last line
_state: dict = {"pipe": None, "prefix": "", "count": 0, "last": int(signal.SIGINT), "generation": 0, "forcing": False,
                "due": None, "exiting": False, "steps": [], "cleanups": {}, "said": None,
                "advice": None}


def ignore(signum, frame) -> None:
    """A handler that does nothing: a command on its way out after a clean stop (:func:`lit3d.utils.stops.on_signals`
    with ``ignore_after_stop``) takes no exception from another signal, but, unlike ``SIG_IGN``, the watcher
    still sees it (a second signal ends the command if its exit hangs). At the end of :func:`watching` it
    becomes ``SIG_IGN``: Python's finalisation puts its own handlers back to the default action."""


@contextlib.contextmanager
def watching(prefix: str = "") -> Iterator[None]:
    """A command's scope: the watcher described in the module doc. ``prefix``: the start of the
    forced exit's line (``"lit3d-reconstruct: "`` for the argparse commands, whose lines carry their
    name). Outside the main thread, or inside another :func:`watching`, the block runs as is."""
    if threading.current_thread() is not threading.main_thread() or _state["pipe"] is not None:
        yield
        return
    r, w = os.pipe()
    os.set_blocking(w, False)
    try:
        previous = signal.set_wakeup_fd(w, warn_on_full_buffer=False)
    except ValueError:  # not the main interpreter's main thread
        os.close(r)
        os.close(w)
        yield
        return
    with _lock:  # a new generation: a forced exit still pending from an earlier scope is void
        generation = _state["generation"] + 1
        _state.update(pipe=(r, w), prefix=prefix, count=0, forcing=False, said=None, advice=None, generation=generation)
    threading.Thread(target=_watch, args=(r, generation), name="lit3d-forced-exit", daemon=True).start()
    try:
        yield
    finally:
        with _lock:
            signal.set_wakeup_fd(previous)
            due = _state["due"] if _state["forcing"] and _state["generation"] == generation else None
            _state.update(pipe=None, generation=generation + 1)
        os.close(w)  # the watcher reads the end of the pipe, closes it and ends
        for s in (signal.SIGINT, signal.SIGTERM):  # the command is on its way out: only the interpreter's end is
            if signal.getsignal(s) is ignore:      # left, which puts Python handlers back to the default (a late
                signal.signal(s, signal.SIG_IGN)   # Ctrl-C would kill it by the signal, not the exit status said)
        if due is not None:  # a forced exit was due within GRACE_S: now, not after Python's own end (seconds
            for stream in (sys.stdout, sys.stderr):  # once torch is loaded, and no daemon thread runs during it)
                with contextlib.suppress(Exception):
                    stream.flush()
            _force(*due, generation=None)


def said(code: int) -> None:
    """The command has said its last line and ends with ``code``: a forced exit from now on adds no
    line and exits with ``code`` (the stop line already said what is kept)."""
    _state["said"] = code


@contextlib.contextmanager
def advice(text: str) -> Iterator[None]:
    """Inside the block the forced exit's line ends with ``text`` (what is kept and how to go on: "resume
    with ... ckpt_path=last") instead of the general "files finished before are kept ..."."""
    before = _state["advice"]
    _state["advice"] = text
    try:
        yield
    finally:
        _state["advice"] = before


@contextlib.contextmanager
def on_forced_exit(cleanup: Callable[[], str | None]) -> Iterator[None]:
    """Inside the block a forced exit first calls ``cleanup()``: it removes what this block leaves
    unfinished and returns a short note for the exit line (or None). Called from the watcher thread
    while the main thread may be anywhere: it must tolerate files that vanish under it."""
    token = object()
    _state["cleanups"][token] = cleanup
    try:
        yield
    finally:
        _state["cleanups"].pop(token, None)


@contextlib.contextmanager
def native_step(what: str, cleanup: Callable[[], str | None] | None = None) -> Iterator[None]:
    """A step the program cannot break off and that is not worth waiting for (``what``, as the exit
    line says it: "while building the Anny body model's cache"): inside, the first SIGINT or SIGTERM
    already ends the command (after :data:`GRACE_S`), calling ``cleanup`` first (see :func:`on_forced_exit`). A stop asked for
    before the step began ends the command as the step begins. Where SIGTERM would kill the process
    outright (its default action: no clean-up), it is handled by the watcher inside the step."""
    with contextlib.ExitStack() as stack:
        if cleanup is not None:
            stack.enter_context(on_forced_exit(cleanup))
        if (_state["pipe"] is not None and threading.current_thread() is threading.main_thread()
                and signal.getsignal(signal.SIGTERM) == signal.SIG_DFL):
            signal.signal(signal.SIGTERM, ignore)
            stack.callback(signal.signal, signal.SIGTERM, signal.SIG_DFL)
        with _lock:
            _state["steps"].append(what)
            asked = _state["count"] > 0 and _state["pipe"] is not None
        if asked:
            _schedule(_state["last"], first=True)
        try:
            yield
        finally:
            with _lock:
                _state["steps"].remove(what)


def now(signum: int) -> None:
    """End the command at once as the watcher would (clean-ups, the line, ``os._exit``), for a handler
    that knows this signal is the second one (``lit3d-train``'s Ctrl-C during training). Outside
    :func:`watching`: returns (the caller goes on with its own stop)."""
    if _state["pipe"] is not None:
        _force(int(signum), None, None)


def _watch(r: int, generation: int) -> None:
    try:
        while data := os.read(r, 64):
            for signum in data:  # one byte per signal
                if signum in LABELS and _state["generation"] == generation and _state["pipe"] is not None:
                    with _lock:
                        _state["count"] += 1
                        _state["last"] = signum
                        count, in_step = _state["count"], bool(_state["steps"])
                    if count >= 2 or in_step:
                        _schedule(signum, first=count < 2)
    except OSError:
        pass
    finally:
        with contextlib.suppress(OSError):
            os.close(r)


def _schedule(signum: int, first: bool) -> None:
    """End the process in :data:`GRACE_S` unless it has ended by then (once per scope)."""
    with _lock:
        if _state["forcing"]:
            return
        _state["forcing"] = True
        generation, step = _state["generation"], (_state["steps"] or [None])[-1]
        _state["due"] = (signum, step if first else None)
    timer = threading.Timer(GRACE_S, _force, (*_state["due"], generation))
    timer.daemon = True
    timer.start()


GENERAL_ADVICE = "files finished before are kept, and the next run clears what an interrupted one leaves"


def exit_line(signum: int, step: str | None, notes: list[str], advice_text: str | None = None) -> str:
    """The forced exit's line (without the command's prefix): what stopped it, what was left unfinished,
    and ``advice_text`` (default :data:`GENERAL_ADVICE`)."""
    label = LABELS.get(signum, signal.Signals(signum).name)
    what = f"stopped by {label} {step}" if step else f"stopped by a second {label}"
    kept = "; ".join(notes) if notes else "nothing was half-written"
    return f"error: {what}; ended at once, without the clean stop: {kept}; {advice_text or GENERAL_ADVICE}"


def _force(signum: int, step: str | None, generation: int | None) -> None:
    """The forced exit (module doc); ``generation``: the scope it was due in (None: now, whatever the scope)."""
    with _lock:
        if generation is not None and _state["generation"] != generation:
            return  # the scope ended (and forced the exit itself), or a forked child
        ending = _state["exiting"]
        _state["exiting"] = True
    if ending:  # another thread is ending the process: wait for it
        threading.Event().wait(5.0)
        return
    notes = []
    for cleanup in list(_state["cleanups"].values()):
        try:
            note = cleanup()
        except Exception as exc:  # a clean-up that fails must not keep the process alive
            note = f"a clean-up failed ({type(exc).__name__}: {exc})"
        if note:
            notes.append(note)
    code = _state["said"]
    if code is None:
        code = 128 + signum
        line = _state["prefix"] + exit_line(signum, step, notes, _state["advice"]) + "\n"
        with contextlib.suppress(OSError):
            os.write(2, line.encode("utf-8", "replace"))  # not sys.stderr: the main thread may hold its lock
    os._exit(code)


def _off_in_child() -> None:
    """In a forked child: no watching (its signals are its own), fresh lock, pipe closed."""
    global _lock
    _lock = threading.Lock()
    pipe = _state["pipe"]
    _state.update(pipe=None, generation=_state["generation"] + 1, steps=[], cleanups={}, forcing=False, exiting=False)
    if pipe is not None:
        with contextlib.suppress(ValueError, OSError):
            signal.set_wakeup_fd(-1)
        for fd in pipe:
            with contextlib.suppress(OSError):
                os.close(fd)


os.register_at_fork(after_in_child=_off_in_child)
