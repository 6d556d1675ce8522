"""The CLI's edges across subcommands: a bad flag or path is one line and exit 2, never a traceback."""

from __future__ import annotations

import pytest

from tests.conftest import run_pfp

pytestmark = pytest.mark.proc


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["schemas", "--dir", "/proc/no-such-dir/x"], "cannot write"),
        (
            ["plan", "examples/x.yaml", "--planner", "optimal", "--cells", "50000"],
            "--cells: must be 10 to 5000",
        ),
        (["bench", "quality", "--cells", "0"], "--cells: must be 10 to 5000"),
        (["bench", "quality", "--cells", "-5"], "--cells: must be 10 to 5000"),
    ],
)
def test_cli_edges_are_one_line_exit_2(args, fragment):
    out = run_pfp(*args, timeout=60)
    assert out.returncode == 2, out.stderr
    assert "Traceback" not in out.stderr
    assert fragment in out.stderr
