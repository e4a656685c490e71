# SPDX-License-Identifier: GPL-3.0-or-later
"""Ctrl-C and SIGTERM in the batch commands: they stop the command at the next check (between
frames, objects, chunks and inside a long precompute) instead of being ignored by Blender or
printed as a handler error. What was received is the session's (`model.runtime.Signals`)."""

from __future__ import annotations

import signal

from ..session import SESSION


class Interrupted(BaseException):
    """Ctrl-C or SIGTERM: stop now (a BaseException, so no `except Exception` swallows it)."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def _on_signal(signum, _frame):
    SESSION.signals.received.append(signum)
    if not SESSION.signals.deferring:
        raise Interrupted(signum)


def watch() -> None:
    """Ctrl-C and SIGTERM raise `Interrupted` (Blender's own handlers would ignore them). Again
    after loading a file: Blender installs its handlers then."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _on_signal)


class deferred:
    """While Blender runs Python callbacks (frame handlers), a signal is only recorded: raised
    there, Blender would print it as a handler error and go on. `check()` raises it after."""

    def __enter__(self):
        SESSION.signals.deferring += 1

    def __exit__(self, *exc):
        SESSION.signals.deferring -= 1


def requested() -> bool:
    """Whether Ctrl-C or SIGTERM came (always False outside the batch commands)."""
    return SESSION.signals.requested()


def check() -> None:
    """Raises `Interrupted` if a signal came while Blender was running Python handlers."""
    if SESSION.signals.received:
        raise Interrupted(SESSION.signals.received[0])
