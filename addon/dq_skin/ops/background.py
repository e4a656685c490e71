# SPDX-License-Identifier: GPL-3.0-or-later
"""Operators whose work takes seconds: Blender data is read first, the computation runs as
`dqskin` jobs on the core's own thread (a `dqskin.Job`: no Python runs there, since
Blender runs its operators, evaluation and UI with the GIL released and a Python thread running
beside them is a hazard) while the UI polls their progress and Esc cancels them, and Blender
data is written only once they have finished. Cancelled or failed, nothing is changed. From
scripts and the command line (`execute`) the same jobs run while a progress bar shows on the
terminal, and Ctrl-C cancels them."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import bpy

from .. import dqskin
from ..progress import Progress

# How often the UI polls the jobs.
POLL_SECONDS = 0.1


@dataclass
class Plan:
    """What an operator does: `steps`, each `(start, share)`: `start()` starts one `dqskin` job
    (which has `done`, `total`, `finished`, `cancel()` and `result()`), run one after the other,
    `share` its part of the progress (its vertices); then `finish(context, results)` in
    Blender's thread, with the jobs' results in order, which returns the report's text; `label`
    names the work in the progress bar."""

    steps: Sequence[tuple[Callable[[], Any], int]]
    finish: Callable[[Any, list], str]
    label: str


class Worker:
    """A plan's jobs, one after the other, advanced from Blender's thread."""

    def __init__(self, plan: Plan):
        self.plan = plan
        self.results: list = []
        self.job = None
        self.cancelled = False
        self.error: BaseException | None = None

    def advance(self) -> bool:
        """Collects the running job if it has finished and starts the next; True once every
        step has ended, one failed, or the plan was cancelled."""
        while True:
            if self.job is not None:
                if not self.job.finished:
                    return False
                try:
                    self.results.append(self.job.result())
                except (ValueError, TypeError, RuntimeError, dqskin.Cancelled) as e:  # RuntimeError: dqskin's internal error
                    self.error = e
                self.job = None
                if self.error is not None:
                    return True
            if self.cancelled:
                self.error = self.error or dqskin.Cancelled(f"{self.plan.label} was cancelled")
                return True
            if len(self.results) == len(self.plan.steps):
                return True
            try:
                self.job = self.plan.steps[len(self.results)][0]()
            except (ValueError, TypeError, RuntimeError) as e:
                self.error = e
                return True

    def cancel(self) -> None:
        self.cancelled = True
        if self.job is not None:
            self.job.cancel()

    def fraction(self) -> float:
        shares = [max(share, 1) for _start, share in self.plan.steps]
        done = sum(shares[: len(self.results)])
        if self.job is not None:
            done += shares[len(self.results)] * self.job.done / max(self.job.total, 1)
        return done / max(sum(shares), 1)


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
        worker = Worker(plan)
        bar = Progress(context, 1000, plan.label)
        try:
            while not worker.advance():
                worker.job.wait(POLL_SECONDS)
                bar.set(int(1000 * worker.fraction()))
        except BaseException:  # Ctrl-C: the job stops too
            worker.cancel()
            raise
        finally:
            bar.end()
        if worker.error is not None:
            self.report({"ERROR"}, f"{plan.label} failed, nothing changed: {worker.error}")
            return {"CANCELLED"}
        return self._finish(context, plan, worker.results)

    def invoke(self, context, event):
        if context.window is None or bpy.app.background:
            return self.execute(context)
        plan = self.plan(context)
        if isinstance(plan, str):
            self.report({"ERROR"}, plan)
            return {"CANCELLED"}
        self._worker = Worker(plan)
        wm = context.window_manager
        self._timer = wm.event_timer_add(POLL_SECONDS, window=context.window)
        wm.progress_begin(0, 1000)
        wm.modal_handler_add(self)
        context.workspace.status_text_set(f"{plan.label}: Esc to cancel")
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        worker = self._worker
        if event.type == "ESC" and event.value == "PRESS":
            worker.cancel()
        if event.type != "TIMER" and not worker.cancelled:
            return {"PASS_THROUGH"}
        ended = worker.advance()
        context.window_manager.progress_update(int(1000 * worker.fraction()))
        if not ended:
            return {"RUNNING_MODAL"}
        self._end(context)
        if worker.cancelled or isinstance(worker.error, dqskin.Cancelled):
            self.report({"WARNING"}, f"{worker.plan.label} cancelled, nothing changed")
            return {"CANCELLED"}
        if worker.error is not None:
            self.report({"ERROR"}, f"{worker.plan.label} failed, nothing changed: {worker.error}")
            return {"CANCELLED"}
        return self._finish(context, worker.plan, worker.results)

    def _end(self, context) -> None:
        wm = context.window_manager
        wm.event_timer_remove(self._timer)
        wm.progress_end()
        context.workspace.status_text_set(None)

    def _finish(self, context, plan: Plan, results: list):
        text = plan.finish(context, results)
        self.report({"INFO"}, text)
        return {"FINISHED"}
