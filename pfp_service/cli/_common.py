"""Argument types shared by several subcommands: checked at the edge, one-line errors."""

from __future__ import annotations

import argparse
import math


def positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text!r}")
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


def non_negative_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"must be a finite number >= 0, got {text!r}")
    return value


def positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {text!r}")
    return value
