"""The sans-I/O planning core: threat field, stepper, preview driver and metrics.

Nothing in this package opens a socket, reads a file, the clock or the
environment. Time, when it matters, is a parameter.

The names below are loaded on first use (PEP 562), not on import: importing any
module of the core runs this file first, and ``core.options`` (the choices a user
names) must stay importable without the compiled kernels, so ``pfp --help`` and a
refused hostile file never pay for numba (issue 35).
"""

from __future__ import annotations

import importlib
import sys
import types
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from pfp_service.core.params import ESCAPES, PlannerParams, Resolved, resolve
    from pfp_service.core.plan import PlanResult, PlanStatus, Scheduled, plan
    from pfp_service.core.stepper import Advice, Stepper, StepStatus
    from pfp_service.core.threat import Threat, ThreatField

__all__ = [
    "ESCAPES",
    "Advice",
    "PlanResult",
    "PlanStatus",
    "PlannerParams",
    "Resolved",
    "Scheduled",
    "StepStatus",
    "Stepper",
    "Threat",
    "ThreatField",
    "plan",
    "resolve",
]

_HOME = {
    "ESCAPES": "params",
    "PlannerParams": "params",
    "Resolved": "params",
    "resolve": "params",
    "PlanResult": "plan",
    "PlanStatus": "plan",
    "Scheduled": "plan",
    "plan": "plan",
    "Advice": "stepper",
    "Stepper": "stepper",
    "StepStatus": "stepper",
    "Threat": "threat",
    "ThreatField": "threat",
}


def __getattr__(name: str) -> Any:
    home = _HOME.get(name)
    if home is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{home}"), name)
    globals()[name] = value  # once: later lookups are plain attribute reads
    return value


class _Core(types.ModuleType):
    """This package, keeping ``core.plan`` the function ``plan`` as the eager import did.

    Loading the submodule ``core.plan`` makes the import system bind it to the package's name
    ``plan``, which would shadow the function for ``from pfp_service.core import plan``.
    """

    def __setattr__(self, name: str, value: Any) -> None:
        if name == "plan" and isinstance(value, types.ModuleType):
            return  # the submodule stays in sys.modules; the name stays the function's
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Core
