"""The one progress bar. Engines never print: they take ``progress`` and call it.

``progress`` may be False/None (silent), True (a rich bar on stderr, shown from the first
update so that an input error found before any work stays the only line on stderr), or a
callable ``progress(done, total)`` of the caller's own.
"""
from __future__ import annotations

import time
from typing import Callable, Optional, Union

ProgressArg = Union[bool, None, Callable[[int, Optional[int]], None]]


class Progress:
    """Context manager; ``update(done, status)`` reports ``done`` items of ``total`` (None: unknown)
    and, on the bar only, a short status text (e.g. the current estimate)."""

    def __init__(self, progress: ProgressArg, total: Optional[int], label: str, unit: str = "frames") -> None:
        self._callback = progress if callable(progress) else None
        self._enabled = progress is True
        self.total, self.label, self.unit = total, label, unit
        self._bar = None
        self._done = 0
        self._start = time.perf_counter()

    def __enter__(self) -> Progress:
        return self

    def update(self, done: int, status: str = "") -> None:
        self._done = done
        if self._callback is not None:
            self._callback(done, self.total)
        if not self._enabled:
            return
        if self._bar is None:
            from rich.console import Console
            from rich.progress import BarColumn, MofNCompleteColumn, TextColumn, TimeElapsedColumn, TimeRemainingColumn
            from rich.progress import Progress as RichProgress
            self._bar = RichProgress(TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
                                     TextColumn("{task.fields[rate]}"), TextColumn("{task.fields[status]}"),
                                     TimeElapsedColumn(), TimeRemainingColumn(),
                                     console=Console(stderr=True), transient=False)
            self._bar.__enter__()
            self._task = self._bar.add_task(self.label, total=self.total, rate="", status="")
        rate = done / max(1e-9, time.perf_counter() - self._start)
        self._bar.update(self._task, completed=done, rate=f"{rate:.1f} {self.unit}/s", status=status)

    def advance(self, count: int = 1) -> None:
        self.update(self._done + count)

    def __exit__(self, *exc) -> bool:
        if self._bar is not None:
            self._bar.update(self._task, total=self._done, completed=self._done)
            self._bar.__exit__(*exc)
        return False
