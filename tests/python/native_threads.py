"""The threads of dqskin's own jobs in this process, by name (`/proc` on Linux)."""

from __future__ import annotations

import os
import time
from pathlib import Path


def threads_named(name: str) -> int | None:
    """How many of this process's threads are called `name` (None where /proc is missing)."""
    tasks = Path(f"/proc/{os.getpid()}/task")
    if not tasks.is_dir():
        return None
    names = []
    for t in tasks.iterdir():
        try:
            names.append((t / "comm").read_text().strip())
        except OSError:
            pass  # ended meanwhile
    return names.count(name)


def wait_until_none_named(name: str, seconds: float = 5.0) -> None:
    """Waits until no thread is called `name` (fails after `seconds`)."""
    end = time.monotonic() + seconds
    while threads_named(name) not in (0, None):
        assert time.monotonic() < end, f"a thread called {name!r} is still running"
        time.sleep(0.01)
