"""Ids in the order people count them: ``m2`` before ``m10`` (natural sort), for every listed id."""

from __future__ import annotations

import re
from collections.abc import Iterable
from typing import TypeVar

__all__ = ["natural_key", "natural_sorted"]

_DIGITS = re.compile(r"(\d+)")
T = TypeVar("T")


def natural_key(text: str) -> tuple[tuple[int, int | str], ...]:
    """A sort key that compares runs of digits as numbers: ``m2 < m10 < n1``; case-insensitive letters.

    Each part is tagged (0: number, 1: text) so numbers and text never compare with each other.
    """
    return tuple(
        (0, int(part)) if part.isdigit() else (1, part.casefold()) for part in _DIGITS.split(text) if part
    )


def natural_sorted(ids: Iterable[str]) -> list[str]:
    """``ids`` in natural order (see ``natural_key``)."""
    return sorted(ids, key=natural_key)
