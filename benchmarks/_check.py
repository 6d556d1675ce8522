"""``--check``: a benchmark with targets exits 1 when one is ``[MISSED]``, 0 when all are met.

So a benchmark can gate a pipeline (``pfp bench engine --check && deploy``).
Without ``--check`` a benchmark reports and exits 0, as a measurement does.
A target that could not be measured (``n/a``, ``None``) is not a miss.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterable

__all__ = ["add_check_arg", "exit_code"]


def add_check_arg(p: argparse.ArgumentParser) -> None:
    """Declare ``--check`` on one benchmark's parser."""
    p.add_argument(
        "--check",
        action="store_true",
        help="exit 1 when a target is missed, 0 when all are met (to gate a pipeline)",
    )


def exit_code(met: Iterable[bool | None], check: bool) -> int:
    """The benchmark's exit code: 1 with ``check`` when any target is missed (``False``), else 0.

    Args:
        met: each target's verdict: ``True`` met, ``False`` missed, ``None`` not measured.
        check: whether ``--check`` was given.
    """
    return 1 if check and any(m is False for m in met) else 0
