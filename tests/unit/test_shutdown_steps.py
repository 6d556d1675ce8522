"""``node.shutdown.run_steps``: a planner's stop, a step at a time, naming the slow ones."""

from __future__ import annotations

import logging

import pytest

from pfp_service.node.shutdown import SLOW_S, run_steps

pytestmark = pytest.mark.unit


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def _fields(caplog: pytest.LogCaptureFixture) -> list[dict]:
    return [r.fields for r in caplog.records if r.getMessage() == "slow stop"]  # type: ignore[attr-defined]


def test_a_slow_step_is_named_with_its_seconds_and_quick_ones_are_not(caplog):
    clock, log = Clock(), logging.getLogger("pfp.test.shutdown")
    ran: list[str] = []

    def step(name: str, s: float):
        def run() -> None:
            ran.append(name)
            clock.t += s

        return (name, run)

    with caplog.at_level(logging.WARNING, logger="pfp.test.shutdown"):
        took = run_steps([step("loop", 0.01), step("previews", SLOW_S + 3.2), step("trace", 0.0)], log, clock)
    assert ran == ["loop", "previews", "trace"] and took["previews"] == pytest.approx(SLOW_S + 3.2)
    assert _fields(caplog) == [
        {"steps_s": {"previews": round(SLOW_S + 3.2, 2)}, "total_s": round(SLOW_S + 3.21, 2)}
    ]


def test_quick_steps_say_nothing_and_a_step_that_raises_stops_the_rest_and_is_still_timed(caplog):
    clock, log = Clock(), logging.getLogger("pfp.test.shutdown")
    with caplog.at_level(logging.WARNING, logger="pfp.test.shutdown"):
        run_steps([("a", lambda: None), ("b", lambda: None)], log, clock)
    assert _fields(caplog) == []

    def fails() -> None:
        clock.t += 2 * SLOW_S
        raise RuntimeError("worker would not die")

    never: list[str] = []
    with caplog.at_level(logging.WARNING, logger="pfp.test.shutdown"), pytest.raises(RuntimeError):
        run_steps([("deliberators", fails), ("sights", lambda: never.append("sights"))], log, clock)
    assert never == [] and _fields(caplog) == [
        {"steps_s": {"deliberators": 2 * SLOW_S}, "total_s": 2 * SLOW_S}
    ]
