"""The sans-I/O planning core: threat field, stepper, preview driver and metrics.

Nothing in this package opens a socket, reads a file, the clock or the
environment. Time, when it matters, is a parameter.
"""

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
