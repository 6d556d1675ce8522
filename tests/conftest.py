"""Shared fixtures, the test tiers, and helpers to run the CLI as a user would.

Every test carries exactly one tier marker, named by what it starts (TIERS below): a module whose
tests all share a tier says so once, ``pytestmark = pytest.mark.<tier>``; a module of mixed tiers
marks each test instead, so that ``-m unit`` selects exactly the unit tests (pytest's ``-m``
sees a module's marker and a test's own together).  The tiers are enforced, not only declared:
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


# How a test runs beside others under ``make test``'s two workers (``-n 2 --dist loadgroup``).
PLACEMENT: dict[str, str] = {
    "alone": (
        "asserts a wall-clock bound of the product (a reconnect within 1.5 s, a page within 3 s) that a "
        "test running beside it could break: make test runs these one at a time, after the rest"
    ),
    "spread": (
        "its module's shared fixtures are cheap enough to set up once per worker: its tests are "
        "spread over the workers instead of kept on one"
    ),
}


def pytest_configure(config: pytest.Config) -> None:
    for name, what in TIERS.items():
        config.addinivalue_line("markers", f"{name}: test tier: {what}")
    for name, what in PLACEMENT.items():
        config.addinivalue_line("markers", f"{name}: {what}")


def _tiers_of(item: pytest.Item) -> set[str]:
    return {mark.name for mark in item.iter_markers() if mark.name in TIERS}


def _tier_of(item: pytest.Item) -> str | None:
    tiers = _tiers_of(item)
    return tiers.pop() if len(tiers) == 1 else None


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    missing = [item.nodeid for item in items if not _tiers_of(item)]
    if missing:
        raise pytest.UsageError(
            "tests without a tier marker (one of " + ", ".join(TIERS) + "): " + ", ".join(missing[:10])
        )
    mixed = [f"{item.nodeid} {sorted(_tiers_of(item))}" for item in items if len(_tiers_of(item)) > 1]
    if mixed:
        raise pytest.UsageError(
            "tests with more than one tier (mark each test of a mixed module, not the module): "
            + ", ".join(mixed[:10])
        )
    # dearest tier first (TIERS' order reversed), each in its collected order: under ``make test``'s two
    # workers the long tests start early and the thousands of short in-process ones fill the end, so
    # neither worker waits idle for the other's last long test (make test warms the planner's kernels
    # into the cache before the workers start, so no planner compiles them)
    rank = {name: i for i, name in enumerate(TIERS)}
    items.sort(key=lambda item: -rank[_tier_of(item) or "unit"])
    for item in items:
        if _shares_a_fixture(item) and item.get_closest_marker("spread") is None:
            item.add_marker(pytest.mark.xdist_group(item.nodeid.split("::", 1)[0]))


def _shares_a_fixture(item: pytest.Item) -> bool:
    """Whether a test uses a module- or class-scoped fixture (a planner shared by a module, say).

    Under ``-n 2 --dist loadgroup`` (``make test``'s proc tier) such a test runs on the worker that
    holds the rest of its module, so the shared planner starts once, not once per worker; every other
    test goes to whichever worker is free, so one long module (test_cli_edges' 58 commands) does not
    keep the other worker idle.  A session fixture is set up once per worker whatever is grouped.
    """
    info = getattr(item, "_fixtureinfo", None)
    if info is None:
        return False
    return any(
        d.scope in ("module", "class", "package") for chain in info.name2fixturedefs.values() for d in chain
    )


class TierViolation(AssertionError):
    """A test started something its tier does not allow."""


# Subprocesses started in this process, counted by an audit hook: a module- or session-scoped fixture
# is set up before ``_enforce_tier`` below patches ``Popen``, so a ``net`` test whose fixture starts a
# planner would otherwise pass as in-process.  Each fixture that starts one is remembered, and every
# unit or net test that uses it fails in its setup, whichever test set the fixture up first.
_started = [0]
_starting_fixtures: set[int] = set()  # id() of each FixtureDef whose setup started a subprocess


def _count_subprocesses(event: str, _args: tuple) -> None:
    if event == "subprocess.Popen":
        _started[0] += 1


sys.addaudithook(_count_subprocesses)


@pytest.hookimpl(wrapper=True)
def pytest_fixture_setup(fixturedef, request):
    before = _started[0]
    result = yield
    if _started[0] > before:
        _starting_fixtures.add(id(fixturedef))
    return result


@pytest.hookimpl(wrapper=True)
def pytest_runtest_setup(item: pytest.Item):
    result = yield
    tier = _tier_of(item)
    if tier in ("unit", "net"):
        defs = getattr(item, "_fixtureinfo", None)
        names = [
            name
            for name, chain in (defs.name2fixturedefs.items() if defs is not None else ())
            if any(id(d) in _starting_fixtures for d in chain)
        ]
        if names:
            raise TierViolation(
                f"fixture {', '.join(names)} of this {tier!r} test started a subprocess: mark it proc"
            )
    return result


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


@pytest.fixture(autouse=True)
def _fresh_route_cache():
    """Each test starts with the process's shared route cache empty.

    Which grid serves a route depends on what the cache already holds (a goal another
    unit asked for gets a shared, roomier grid), so without this a test's routes would
    depend on the tests that ran before it in the same process.
    """
    routes = sys.modules.get("pfp_service.core.routes")
    if routes is not None:
        routes.ROUTES.clear()
    yield


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


def pytest_unconfigure(config: pytest.Config) -> None:
    """The test process, like ``pfp``, waits for Zenoh's callback threads before it finalises.

    A test that declared callbacks on a daemon thread (a fleet, a handheld link)
    and closed its session leaves threads that must take the GIL once more;
    doing so during finalisation aborts the worker (``signals.settle_callback_threads``).
    """
    from pfp_service.signals import settle_callback_threads

    settle_callback_threads()
