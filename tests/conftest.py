"""Shared fixtures: the paper's instance and helpers to run the CLI as a user would."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"


@pytest.fixture(autouse=True, scope="session")
def _state_home(tmp_path_factory):
    """Planners started by the tests keep their durable state in a temporary directory."""
    os.environ["XDG_STATE_HOME"] = str(tmp_path_factory.mktemp("state-home"))


def run_pfp(*args: str, timeout: float = 120, **kw) -> subprocess.CompletedProcess[str]:
    """Run ``pfp ARGS`` in a subprocess, exactly as a user would."""
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    return subprocess.run(
        [sys.executable, "-m", "pfp_service", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=kw.pop("cwd", ROOT),
        env=env,
        **kw,
    )


@pytest.fixture
def paper_scenario():
    from pfp_service.scenario import load_scenario

    return load_scenario(EXAMPLES / "paper-simple.yaml")
