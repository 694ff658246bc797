"""Helpers of the tests that stop real ``lit3d-*`` processes with signals (each process started by
``test_interrupt_resume._start``, which writes its stdout and stderr beside ``log`` as .out and .err)."""
from __future__ import annotations

import subprocess
import time
from collections.abc import Callable, Sequence
from pathlib import Path

EXIT_STOPPED = 143  # a stop by SIGTERM or Ctrl-C (lit3d.cli.common.Interrupted)


def signal_when(proc: subprocess.Popen, ready: Callable[[], object], log: Path, signals: Sequence[int],
                timeout: float = 300, gap: float = 0.2) -> int:
    """Send ``signals`` (``gap`` s apart) once ``ready()``; the exit status. The process is killed if
    it is still running at the end."""
    try:
        t0 = time.monotonic()
        while not ready():
            assert proc.poll() is None, f"ended (rc {proc.returncode}) first:\n" + log.with_suffix(".err").read_text()[-3000:]
            assert time.monotonic() - t0 < timeout, "the process did not get there"
            time.sleep(0.02)
        for i, sig in enumerate(signals):
            if i:
                time.sleep(gap)
            proc.send_signal(sig)
        try:
            return proc.wait(timeout=180)
        except subprocess.TimeoutExpired:  # say what the process was doing when it did not stop
            raise AssertionError(f"still running 180 s after {[int(s) for s in signals]}; its stderr ends:\n"
                                 + log.with_suffix(".err").read_text()[-3000:]
                                 + "\nstdout ends:\n" + log.with_suffix(".out").read_text()[-1500:]) from None
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=60)


def stop_line(log: Path, rc: int) -> str:
    """The last stderr line, checked to be the only ``error:`` line, with no traceback, after exit 143."""
    err = log.with_suffix(".err").read_text()
    assert rc == EXIT_STOPPED, f"exit {rc}\n{err[-3000:]}\n{log.with_suffix('.out').read_text()[-1500:]}"
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err[-3000:]
    assert [ln for ln in lines if ln.startswith("error:")] == lines[-1:], err[-3000:]
    return lines[-1]
