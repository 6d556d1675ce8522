"""Shared fixtures, the test tiers, and helpers to run the CLI as a user would.

Every test carries exactly one tier marker, named by what it starts (TIERS below).  A module
sets its tier with ``pytestmark = pytest.mark.<tier>``; a test that starts more than its module
does carries its own marker, which then wins.  The tiers are enforced, not only declared:
a ``unit`` test that starts a subprocess or opens a Zenoh session fails, and so does a ``net``
test that starts a subprocess.  ``make test-fast`` runs ``unit`` and ``net``; ``make test``
runs every tier.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

# tier -> what it may start; the order is from cheapest to dearest
TIERS: dict[str, str] = {
    "unit": "in process only: no subprocess, no Zenoh session",
    "net": "in process, with real Zenoh sessions on loopback; no subprocess",
    "proc": "starts subprocesses: the pfp CLI, or one planner with its clients",
    "multi": "several long-running processes at once: planners, routers, bridges, load generators",
    "browser": "drives the system Chromium against a served page",
}


def pytest_configure(config: pytest.Config) -> None:
    for name, what in TIERS.items():
        config.addinivalue_line("markers", f"{name}: test tier: {what}")


def _tier_of(item: pytest.Item) -> str | None:
    # the closest marker wins: a test's own marker before its module's
    for mark in item.iter_markers():
        if mark.name in TIERS:
            return mark.name
    return None


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    missing = [item.nodeid for item in items if _tier_of(item) is None]
    if missing:
        raise pytest.UsageError(
            "tests without a tier marker (one of " + ", ".join(TIERS) + "): " + ", ".join(missing[:10])
        )


class TierViolation(AssertionError):
    """A test started something its tier does not allow."""


@pytest.fixture(autouse=True)
def _enforce_tier(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch):
    tier = _tier_of(request.node)
    if tier in ("unit", "net"):
        real_init = subprocess.Popen.__init__

        def no_subprocess(self, *args, **kwargs):
            raise TierViolation(f"a {tier!r} test started a subprocess ({args[:1]}): mark it proc or multi")

        monkeypatch.setattr(subprocess.Popen, "__init__", no_subprocess)
        assert real_init is not None
    if tier == "unit":
        import zenoh

        def no_session(*args, **kwargs):
            raise TierViolation("a 'unit' test opened a Zenoh session: mark it net")

        monkeypatch.setattr(zenoh, "open", no_session)
    yield


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


# Hypothesis profiles (``--hypothesis-profile=long``) must be registered before the plugin reads the flag.
import tests.hypothesis_profiles  # noqa: E402, F401
