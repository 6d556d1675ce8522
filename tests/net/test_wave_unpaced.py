"""A wave's shares are not paced: the loop's amortising pause (``node.MIN_TICK_S``) never keeps a unit in danger waiting.

While states keep coming the loop ticks at most every ``MIN_TICK_S``, so that
the states of a few milliseconds share one tick.  A contingency's wave goes out
a share an ``apply`` (``world/wave.py``); were each share to wait for that
pause, a wave of ``k`` shares would take ``k - 1`` pauses more than its work
(BENCHMARKS.md, "A wave's shares without the tick's pause").  The pause is set to a quarter of a second
here, so a wave paced by it takes seconds and one that is not takes a few
milliseconds: the test tells the two apart on any machine.  The wave's points
(its look-aheads, owed once every direction is out) are still paced.
"""

from __future__ import annotations

import os
import time

import pytest
import zenoh

from pfp_service.node import node as node_module
from pfp_service.node.config import ServeConfig, zenoh_config
from pfp_service.node.node import PlannerNode
from pfp_service.wire import keys
from pfp_service.world.wave import WAVE_PER_TICK
from tests.zenoh_util import Inbox, client, free_port, guide_in_a_column, put_in_force, put_json

pytestmark = pytest.mark.net

PAUSE_S = 0.25
N = 3 * WAVE_PER_TICK + 8  # a wave of four shares at least: paced, 0.75 s of pauses or more


def test_a_waves_shares_follow_one_another_without_the_ticks_pause(monkeypatch):
    from pfp_service.node.previews import PreviewService

    real_wait = PreviewService.wait_ready  # previews are not under test: the node waits for no worker
    monkeypatch.setattr(PreviewService, "wait_ready", lambda self, timeout_s=0.0: real_wait(self, 0.0))
    monkeypatch.setattr(node_module, "MIN_TICK_S", PAUSE_S)
    m = "unpaced" + str(os.getpid())
    ep = f"tcp/127.0.0.1:{free_port()}"
    cfg = ServeConfig(mission=m, listen=[ep], unit_stale_s=600.0, lookahead=0)
    session = zenoh.open(zenoh_config(cfg))
    node = PlannerNode(session, cfg)
    ids = [f"u{i:03d}" for i in range(N)]
    try:
        node.start()
        with client(ep) as s:
            inbox = Inbox(s, keys.unit_directions(m))
            put_in_force(
                s, m, {keys.unit_goal(m, u): {"position": [60.0, float(i)]} for i, u in enumerate(ids)}
            )
            answered = guide_in_a_column(s, m, ids, inbox)  # every unit guided once
            assert answered == set(ids)
            time.sleep(2.0)  # the units quiet: only the wave's directions come now
            inbox.sub.undeclare()
            first: dict[str, float] = {}  # each unit's first direction since the threat, timed as it arrives

            def arrived(sample: zenoh.Sample) -> None:
                first.setdefault(str(sample.key_expr).split("/")[-2], time.monotonic())

            sub = s.declare_subscriber(keys.unit_directions(m), arrived)
            # one broad threat across every unit's way: the change reaches them all
            threat = {"position": [30.0, N / 2.0], "sigma_range": float(N), "sigma_lateral": float(N)}
            put_json(s, keys.threat(m, "c"), threat)
            deadline = time.monotonic() + 30
            while len(first) < N and time.monotonic() < deadline:
                time.sleep(0.05)
            sub.undeclare()
            assert sorted(first) == ids, f"{len(first)} of {N} re-directed"
            spread = max(first.values()) - min(first.values())
            # paced, each of the three shares or more after the first waits PAUSE_S
            assert spread < PAUSE_S, f"the wave took {spread:.3f} s: its shares waited for the tick's pause"
    finally:
        node.stop()
        session.close()


def test_a_failing_tick_never_spins_the_loop_while_a_wave_is_owed(monkeypatch):
    """A tick that raises (logged, the planner carries on) is followed by the pause even while directions are
    owed: a loop woken again and again would otherwise retry it as fast as the CPU allows."""
    from pfp_service.node.previews import PreviewService

    real_wait = PreviewService.wait_ready
    monkeypatch.setattr(PreviewService, "wait_ready", lambda self, timeout_s=0.0: real_wait(self, 0.0))
    monkeypatch.setattr(node_module, "MIN_TICK_S", 0.05)
    cfg = ServeConfig(mission="spin" + str(os.getpid()), listen=[f"tcp/127.0.0.1:{free_port()}"], lookahead=0)
    session = zenoh.open(zenoh_config(cfg))
    node = PlannerNode(session, cfg)
    calls: list[float] = []

    def failing() -> None:
        calls.append(time.monotonic())
        raise RuntimeError("a bad batch")

    try:
        node.start()
        monkeypatch.setattr(node.world, "directions_owed", lambda: True)
        monkeypatch.setattr(node, "_tick", failing)
        end = time.monotonic() + 1.0
        while time.monotonic() < end:  # woken every millisecond, as a stream of states would
            node._wake.set()
            time.sleep(0.001)
        n = len(calls)
    finally:
        monkeypatch.undo()
        node.stop()
        session.close()
    assert 1 <= n <= 1.0 / 0.05 + 3, f"{n} failing ticks in 1 s"
