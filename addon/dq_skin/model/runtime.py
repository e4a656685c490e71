# SPDX-License-Identifier: GPL-3.0-or-later
"""Small pieces of session state that are not about one modifier: the exporters running now,
the signals a batch command received, the add-on's last internal error."""

from __future__ import annotations


class Exports:
    """The exporters running now (nested exports are possible), and who to tell when one starts
    or ends."""

    def __init__(self):
        self.running: list[str] = []
        self.listeners: list = []  # called with no arguments when an export starts or ends
        self.scopes: list = []  # open glTF export scopes (its callbacks come in pairs)

    def active(self) -> str:
        """The panel's reason while an exporter runs, else ""."""
        return f"Exporting ({self.running[-1]}): the exporter skins from Blender's Armature modifier" if self.running else ""

    def changed(self) -> None:
        for fn in list(self.listeners):
            fn()


class Signals:
    """Ctrl-C and SIGTERM received by a batch command (see `cli.interrupts`)."""

    def __init__(self):
        self.received: list[int] = []
        self.deferring = 0  # > 0 while Blender runs Python callbacks: a signal is only recorded

    def requested(self) -> bool:
        return bool(self.received)


class Errors:
    """The add-on's last unexpected failure in a handler (the panel shows it), and whether a
    handler is running (they do not nest)."""

    def __init__(self):
        self.last = ""
        self.busy = False


# Where users report bugs (the manifest's website is the project's page).
WEBSITE = "https://github.com/dqskin/dqskin"
ISSUES_URL = f"{WEBSITE}/issues"
