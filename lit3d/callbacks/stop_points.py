"""Batch ends as stop points of an evaluation (``lit3d-eval``'s trainer).

Under :func:`lit3d.utils.stops.on_signals` a Ctrl-C (SIGINT) or SIGTERM is only recorded; this
callback acts on it after the current validation, test or prediction batch by raising
:class:`~lit3d.utils.stops.StopRequested`, which Lightning passes on (a ``KeyboardInterrupt`` it would
end with exit 1 and no word of what was kept). :func:`lit3d.cli.stops.evaluating` turns it into one line.
"""
from __future__ import annotations

import lightning.pytorch as pl

from lit3d.utils.stops import check_stop


class StopPoints(pl.Callback):
    """Calls :func:`lit3d.utils.stops.check_stop` after every validation, test and prediction batch."""

    def on_validation_batch_end(self, *args, **kwargs) -> None:
        check_stop()

    def on_test_batch_end(self, *args, **kwargs) -> None:
        check_stop()

    def on_predict_batch_end(self, *args, **kwargs) -> None:
        check_stop()
