"""A mission's dispersion settings: on or off, the separation of each mobility class, and the right-of-way rule.

Apart from ``dispersion`` (which uses them) so that ``WorldSettings`` can
hold them without importing the unit records.  A unit's separation is its
mobility class's (``SEPARATION_M``, a registry keyed as
``core.mobility.CLASSES``): the class named for it in ``classes``, or else
``default_class``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from pfp_service.core.mobility import CLASSES

__all__ = ["SEPARATION_M", "DispersionSettings"]

# The doctrine's figures: vehicles keep 50 m apart on a tactical march, dismounts on foot 5 m.
SEPARATION_M: Mapping[str, float] = {"foot": 5.0, "wheeled": 50.0, "tracked": 50.0}
assert set(SEPARATION_M) == set(CLASSES), "a mobility class without a separation"


@dataclass(frozen=True)
class DispersionSettings:
    """A mission's dispersion: on or off, separations by class, each unit's class, the right-of-way rule.

    ``deadlock_s``: a unit yielding this long to a unit that has not drawn
    away is in a deadlock; it then backs off for ``backoff_s``.
    ``manned_first``: manned units have right of way over unmanned ones
    (then the smaller id); off, the id alone decides.
    """

    enabled: bool = False
    separation_m: Mapping[str, float] = field(default_factory=lambda: dict(SEPARATION_M))
    default_class: str = "wheeled"
    classes: Mapping[str, str] = field(default_factory=dict)  # unit id -> mobility class
    manned_first: bool = True
    deadlock_s: float = 6.0
    backoff_s: float = 6.0

    def separation(self, unit: str) -> float:
        """The unit's separation in metres, by its class."""
        return self.separation_m[self.classes.get(unit, self.default_class)]
