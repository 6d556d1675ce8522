"""Hypothesis profiles for the property tests that use them (conftest.py stays the lead's).

``profiled()`` is the settings decorator of those tests: under hypothesis's
own default profile (``make test``) it is derandomised (a failure reproduces
on any machine) and small, a few seconds a test; with
``--hypothesis-profile=long`` it searches for real: random, 2,000 examples a
test, a failure printed with the ``@example`` to keep.
"""

from __future__ import annotations

from hypothesis import HealthCheck, settings

__all__ = ["FAST_EXAMPLES", "LONG_EXAMPLES", "profiled"]

FAST_EXAMPLES = 40
LONG_EXAMPLES = 2_000
_SLOW = [HealthCheck.too_slow, HealthCheck.filter_too_much, HealthCheck.data_too_large]

settings.register_profile(
    "long", max_examples=LONG_EXAMPLES, deadline=None, suppress_health_check=_SLOW, print_blob=True
)


def profiled(fast_examples: int = FAST_EXAMPLES) -> settings:
    """The settings of a property test: small and derandomised, unless ``long`` was asked for."""
    if settings.get_current_profile_name() == "long":
        return settings(parent=settings.get_profile("long"))
    return settings(
        max_examples=fast_examples,
        deadline=None,
        derandomize=True,
        suppress_health_check=_SLOW,
        print_blob=True,
    )
