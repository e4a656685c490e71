# SPDX-License-Identifier: GPL-3.0-or-later
"""Operators whose work takes seconds: Blender data is read first, the computation (numpy and
`dqskin` only, the GIL released) runs in a thread while the UI shows its progress and Esc
cancels it, and Blender data is written only once it has finished. Cancelled or failed, nothing
is changed. From scripts and the command line (`execute`) the same work runs on the spot with a
progress bar on the terminal."""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import bpy

from .. import dqskin
from ..progress import Progress

# How often the UI polls the thread.
POLL_SECONDS = 0.1


@dataclass
class Plan:
    """What an operator does: `work(progress)` in the thread (returns the result; `progress(done,
    total)` returns False once cancelled), then `finish(context, result)` in Blender's thread,
    which returns the report's text; `label` names the work in the progress bar."""

    work: Callable[[Callable[[int, int], bool]], Any]
    finish: Callable[[Any, Any], str]
    label: str


class Worker:
    """A plan's work in a thread, with its progress and a cancel flag."""

    def __init__(self, plan: Plan):
        self.plan = plan
        self.done, self.total = 0, 1
        self.cancelled = False
        self.result = None
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._run, name="dq_skin weights", daemon=True)

    def progress(self, done: int, total: int) -> bool:
        self.done, self.total = done, max(total, 1)
        return not self.cancelled

    def _run(self) -> None:
        try:
            self.result = self.plan.work(self.progress)
        except BaseException as e:  # handed to Blender's thread, which reports it
            self.error = e


class BackgroundOperator(bpy.types.Operator):
    """Base of operators that run a `Plan`: subclasses define `plan(context)`, which returns a
    Plan or the text of an error."""

    def plan(self, context) -> Plan | str:
        raise NotImplementedError

    def execute(self, context):
        plan = self.plan(context)
        if isinstance(plan, str):
            self.report({"ERROR"}, plan)
            return {"CANCELLED"}
        bar = Progress(context, 1000, plan.label)
        try:
            result = plan.work(lambda done, total: bar.set(1000 * done // max(total, 1)) or True)
        except (ValueError, TypeError, dqskin.Cancelled) as e:
            self.report({"ERROR"}, f"{plan.label} failed, nothing changed: {e}")
            return {"CANCELLED"}
        finally:
            bar.end()
        return self._finish(context, plan, result)

    def invoke(self, context, event):
        if context.window is None or bpy.app.background:
            return self.execute(context)
        plan = self.plan(context)
        if isinstance(plan, str):
            self.report({"ERROR"}, plan)
            return {"CANCELLED"}
        self._worker = Worker(plan)
        self._worker.thread.start()
        wm = context.window_manager
        self._timer = wm.event_timer_add(POLL_SECONDS, window=context.window)
        wm.progress_begin(0, 1000)
        wm.modal_handler_add(self)
        context.workspace.status_text_set(f"{plan.label}: Esc to cancel")
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        worker = self._worker
        if event.type == "ESC" and event.value == "PRESS":
            worker.cancelled = True
        if event.type != "TIMER" and not worker.cancelled:
            return {"PASS_THROUGH"}
        context.window_manager.progress_update(1000 * worker.done // worker.total)
        if worker.thread.is_alive():
            return {"RUNNING_MODAL"}
        self._end(context)
        if worker.cancelled or isinstance(worker.error, dqskin.Cancelled):
            self.report({"WARNING"}, f"{worker.plan.label} cancelled, nothing changed")
            return {"CANCELLED"}
        if worker.error is not None:
            self.report({"ERROR"}, f"{worker.plan.label} failed, nothing changed: {worker.error}")
            return {"CANCELLED"}
        return self._finish(context, worker.plan, worker.result)

    def _end(self, context) -> None:
        wm = context.window_manager
        wm.event_timer_remove(self._timer)
        wm.progress_end()
        context.workspace.status_text_set(None)

    def _finish(self, context, plan: Plan, result):
        text = plan.finish(context, result)
        self.report({"INFO"}, text)
        return {"FINISHED"}
