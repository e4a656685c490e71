"""The add-on's modules that import nothing of Blender's (its model, the point-cache files),
loaded on their own from `addon/dq_skin`, outside the add-on package, for tests without Blender."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

ADDON = Path(__file__).resolve().parents[2] / "addon" / "dq_skin"


def load(*parts: str):
    """The module at `addon/dq_skin/<parts>.py` (`load("model", "keys")`), loaded afresh."""
    name = "dq_skin_" + "_".join(parts)
    spec = importlib.util.spec_from_file_location(name, ADDON.joinpath(*parts[:-1], parts[-1] + ".py"))
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # (dataclasses look their module up)
    spec.loader.exec_module(module)
    return module
