# SPDX-License-Identifier: GPL-3.0-or-later
"""Progress of long work (bakes, comparisons, batch commands, precomputes): a text bar on the
terminal and Blender's own progress in the UI."""

from __future__ import annotations

import sys
import time


class Progress:
    """Progress on the terminal (a text bar with the time left, redrawn in place), in logs (a
    non-terminal, as on a render farm: the same line, one per line, each time another tenth of
    the work is done, at least every `LOG_SECONDS` while it advances, and at the end) and in the
    UI (`window_manager.progress_*`). A context manager."""

    LOG_SECONDS = 5.0

    def __init__(self, context, total: int, label: str):
        self.wm = getattr(context, "window_manager", None)
        self.total, self.label, self.done = max(total, 1), label, 0
        self.start = time.perf_counter()
        self.tty = sys.stderr.isatty()
        self._logged = (0, self.start)  # in logs: the tenth and the time of the last line
        if self.wm is not None:
            self.wm.progress_begin(0, self.total)

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc) -> None:
        self.end()

    def step(self, count: int = 1) -> None:
        self.set(self.done + count)

    def set(self, done: int) -> None:
        self.done = min(done, self.total)
        if self.wm is not None:
            self.wm.progress_update(self.done)
        finished = self.done == self.total
        if not (self.tty or finished or self._log_due()):
            return
        width = 30
        filled = int(width * self.done / self.total)
        elapsed = time.perf_counter() - self.start
        if finished:
            timing = f"{elapsed:.1f} s"
        else:
            timing = f"{elapsed / self.done * (self.total - self.done):.0f} s left" if self.done else ""
        line = f"{self.label} [{'#' * filled}{'.' * (width - filled)}] {self.done}/{self.total} {timing}"
        if self.tty:
            line = "\r" + line
            sys.stderr.write(line.ljust(getattr(self, "_width", 0)) + ("\n" if finished else ""))
            self._width = len(line)
        else:
            sys.stderr.write(line.rstrip() + "\n")
        sys.stderr.flush()

    def _log_due(self) -> bool:
        """In logs: whether another tenth is done, or `LOG_SECONDS` passed, since the last line."""
        tenth, now = self.done * 10 // self.total, time.perf_counter()
        if tenth > self._logged[0] or now - self._logged[1] >= self.LOG_SECONDS:
            self._logged = (tenth, now)
            return True
        return False

    def end(self) -> None:
        if self.wm is not None:
            self.wm.progress_end()
            self.wm = None
