"""The batch's progress: a bar redrawn in place on a terminal, a plain line per finished run
when the output is a file or a pipe (CI logs keep every line and no carriage return)."""
from __future__ import annotations

import sys
import time
from typing import TextIO

BAR_WIDTH = 24


def format_duration(seconds: float) -> str:
    """'42 s', '3 min 05 s', '2 h 10 min'."""
    seconds = int(round(seconds))
    if seconds < 60:
        return f'{seconds} s'
    if seconds < 3600:
        return f'{seconds // 60} min {seconds % 60:02d} s'
    return f'{seconds // 3600} h {seconds % 3600 // 60:02d} min'


class Progress:
    """Counts runs as they finish; ``total`` runs to do in this batch (already complete
    ones are not counted), ETA from the pace of the runs finished so far."""

    def __init__(self, total: int, stream: TextIO | None = None,
                 interactive: bool | None = None) -> None:
        self.total = total
        self.stream = stream if stream is not None else sys.stdout
        self.interactive = self.stream.isatty() if interactive is None else interactive
        self.done = 0
        self.failed = 0
        self._started = time.monotonic()

    @property
    def remaining(self) -> int:
        return self.total - self.done - self.failed

    def eta_s(self) -> float | None:
        finished = self.done + self.failed
        if finished == 0:
            return None
        return (time.monotonic() - self._started) / finished * self.remaining

    def status(self) -> str:
        eta = self.eta_s()
        return (f'{self.done + self.failed}/{self.total}: done {self.done}, failed '
                f'{self.failed}, remaining {self.remaining}, ETA '
                f'{"?" if eta is None else format_duration(eta)}')

    def start(self) -> None:
        if self.interactive:
            self._draw()

    def finished(self, ok: bool, label: str) -> None:
        """A run finished (``ok``, or failed); ``label`` says which."""
        if ok:
            self.done += 1
        else:
            self.failed += 1
        if self.interactive:
            if not ok:  # a failure stays on the screen above the bar
                self.stream.write(f'\r\033[Kfailed: {label}\n')
            self._draw()
        else:
            self.stream.write(f'{"ok    " if ok else "FAILED"} {label}  [{self.status()}]\n')
        self.stream.flush()

    def refresh(self) -> None:
        """Redraw the bar (its ETA moves between runs too)."""
        if self.interactive:
            self._draw()

    def _draw(self) -> None:
        filled = BAR_WIDTH * (self.done + self.failed) // max(self.total, 1)
        bar = '#' * filled + '-' * (BAR_WIDTH - filled)
        self.stream.write(f'\r\033[K[{bar}] {self.status()}')
        self.stream.flush()

    def close(self) -> None:
        if self.interactive:
            self.stream.write('\n')
            self.stream.flush()
