"""Argument types checked at the edge: the numbers a flag takes, with the bounds a file field has.

Shared by the commands (``pfp_service.cli``, the clients' commands) and the benchmarks, which sit
beside the commands, not under them: so they live here, below both, and import only ``errors``.
An argument type raises ``argparse.ArgumentTypeError``, which argparse turns into one usage line
and exit 2.
"""

from __future__ import annotations

import argparse
import math
from typing import Any

from pfp_service.errors import FINITE_LIMIT  # the file fields' bound: numeric flags share it

__all__ = [
    "MAX_CELLS",
    "MIN_CELLS",
    "bounded_int",
    "grid_cells",
    "non_negative_float",
    "positive_float",
    "positive_int",
]


def positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (math.isfinite(value) and 0 < value <= FINITE_LIMIT):
        raise argparse.ArgumentTypeError(
            f"must be a finite number > 0 (at most {FINITE_LIMIT:g}), got {text!r}"
        )
    return value


MIN_CELLS, MAX_CELLS = 10, 5000  # 5000^2 cells of 16 edges is about 3 GB: past that, numpy runs out


def grid_cells(text: str) -> int:
    """``--cells``: the optimal planner's grid resolution, ``MIN_CELLS`` to ``MAX_CELLS``."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if not MIN_CELLS <= value <= MAX_CELLS:
        raise argparse.ArgumentTypeError(f"must be {MIN_CELLS} to {MAX_CELLS}, got {text!r}")
    return value


def bounded_int(lo: int, hi: int) -> Any:
    """An argument type: a whole number from ``lo`` to ``hi``, the same bounds a file field has."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"must be {lo} to {hi:,}, got {text!r}")
        return value

    parse.__name__ = "whole number"
    return parse


def non_negative_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (math.isfinite(value) and 0 <= value <= FINITE_LIMIT):
        raise argparse.ArgumentTypeError(
            f"must be a finite number >= 0 (at most {FINITE_LIMIT:g}), got {text!r}"
        )
    return value


def positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {text!r}")
    return value
