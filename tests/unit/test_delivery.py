"""Acknowledged writes (``wire.delivery``): goals and threats put before a planner runs are in force once it starts.

The bars: a threat and a goal put before ``pfp serve`` starts are in force
within 2 s of its first status; a goal deleted before it starts stays deleted,
also when the put and the delete came from different writers and are asked
again in either order.  Clients run as users run them (``pfp inject``,
``pfp fleet`` started before ``pfp serve``); the cross-writer order is checked
with two in-process writers and raw zenoh sessions.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
import uuid
from contextlib import contextmanager
from pathlib import Path

import msgspec
import pytest
import zenoh

from pfp_service.wire import Goal, ThreatUpdate, encode, keys
from pfp_service.wire.delivery import Deliverer, WriteMark, WriteOrder, decode_mark
from tests.zenoh_util import ROOT, client, free_port


# -- the order of writes: sans-I/O ------------------------------------------------------
@pytest.mark.unit
def test_an_older_write_asked_again_is_superseded_and_a_repeat_is_a_duplicate():
    order = WriteOrder()
    put = WriteMark(t=100.0, writer="a")
    delete = WriteMark(t=101.0, writer="b", delete=True)
    assert order.admit("k", delete, 0.0, asked=True) == "applied"  # no planner saw either live
    assert order.admit("k", put, 0.0, asked=True) == "superseded"  # the older put, asked after the delete
    assert order.admit("k", delete, 0.0) == "duplicate"  # the delete's put after its query
    assert order.admit("other", put, 0.0, asked=True) == "applied"  # per key


@pytest.mark.unit
def test_live_puts_apply_in_the_order_they_arrive_whatever_the_clocks():
    order = WriteOrder()
    ahead, behind = WriteMark(t=200.0, writer="a"), WriteMark(t=100.0, writer="b")
    assert order.admit("k", ahead, 0.0) == "applied"
    assert order.admit("k", behind, 0.0) == "applied"  # a writer whose clock is behind, live: still applied
    assert order.admit("k", behind, 0.0, asked=True) == "duplicate"  # its query: the write in force
    assert order.admit("k", ahead, 0.0, asked=True) == "superseded"  # a's query came late: b's is newer here


@pytest.mark.unit
def test_a_write_without_a_mark_counts_as_written_when_received():
    order = WriteOrder()
    assert order.admit("k", None, 50.0) == "applied"  # a raw zenoh put at 50
    assert order.admit("k", WriteMark(t=49.0, writer="a"), 51.0, asked=True) == "superseded"
    assert order.admit("k", WriteMark(t=52.0, writer="a"), 53.0, asked=True) == "applied"


@pytest.mark.unit
def test_the_order_is_bounded():
    order = WriteOrder(max_keys=3)
    for i in range(10):
        assert order.admit(f"k{i}", WriteMark(t=1.0), 0.0) == "applied"
    assert len(order._last) == 3


@pytest.mark.unit
@pytest.mark.parametrize("data", [None, b"", b"x" * 300, b"{", b'{"t": "soon"}', b"[1]"])
def test_an_attachment_that_is_no_mark_of_ours_is_none(data):
    assert decode_mark(data) is None


@pytest.mark.unit
def test_a_mark_round_trips():
    mark = WriteMark(t=1.5, writer="ab", delete=True)
    assert decode_mark(msgspec.json.encode(mark)) == mark


# -- real processes ----------------------------------------------------------------------
def _router(endpoint: str) -> zenoh.Session:
    conf = zenoh.Config()
    conf.insert_json5("mode", '"router"')
    conf.insert_json5("listen/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(conf)


@contextmanager
def _pfp(*args: str):
    """``pfp ARGS`` running in the background; yields (process, log file); stopped with SIGTERM."""
    log = tempfile.TemporaryFile("w+")  # noqa: SIM115 - closed below, after the process
    proc = subprocess.Popen(
        [sys.executable, "-m", "pfp_service", *args],
        cwd=ROOT,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
        stdout=log,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        yield proc, log
    finally:
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        log.close()


def _text(log) -> str:
    log.seek(0)
    return log.read()


def _wait_for(what: str, cond, timeout_s: float, logs=()) -> float:
    """Poll ``cond`` until true; returns the monotonic time it became true."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if cond():
            return time.monotonic()
        time.sleep(0.05)
    raise AssertionError(f"{what} within {timeout_s:g} s\n" + "\n---\n".join(_text(g)[-3000:] for g in logs))


def _world(session: zenoh.Session, mission: str) -> dict | None:
    for r in session.get(keys.worlds(mission), timeout=1.0):
        if r.ok is not None:
            return json.loads(r.ok.payload.to_bytes())
    return None


def _goals(world: dict) -> dict[str, list[float] | None]:
    return {u["id"]: u.get("goal") for u in world.get("units", [])}


def _threats(world: dict) -> set[str]:
    return {t["id"] for t in world.get("threats", [])}


SCRIPT = """\
name: early
duration_s: 120
timeline:
  - {do: add_threat, threat: t1, position: [4, 6], sigma_range: 1.0, sigma_lateral: 0.7}
  - {do: set_goal, unit: u1, position: [10, 10]}
  - {do: set_goal, unit: u2, position: [5, 5]}
  - {do: cancel_goal, unit: u2}
"""

TEAM = """\
name: early-fleet
units:
  - {id: f1, start: [0, 0], goal: [12, 3], speed_mps: 1.5}
"""


@pytest.mark.multi
@pytest.mark.alone
def test_inject_and_fleet_started_before_pfp_serve_are_in_force_within_2s_of_its_first_status(tmp_path):
    """``pfp serve`` is the router here, so inject and fleet also wait for the router itself."""
    mission = "e" + uuid.uuid4().hex[:8]
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    script, team = tmp_path / "early.yaml", tmp_path / "team.yaml"
    script.write_text(SCRIPT)
    team.write_text(TEAM)
    common = ("--connect", endpoint, "--mission", mission)
    with (
        _pfp("inject", str(script), *common) as (inject, ilog),
        _pfp("fleet", "--team", str(team), *common, "--duration-s", "600") as (_fleet, flog),
    ):
        _wait_for("inject waits for the router", lambda: "waiting for the router" in _text(ilog), 60, [ilog])
        _wait_for("fleet waits for the router", lambda: "waiting for the router" in _text(flog), 60, [flog])
        state = tmp_path / "state"
        with _pfp("serve", "--listen", endpoint, "--mission", mission, "--state-dir", str(state)) as (
            _p,
            slog,
        ):
            logs = [ilog, flog, slog]

            def first_status() -> bool:
                try:
                    with client(endpoint) as s:
                        return any(
                            r.ok is not None for r in s.get(keys.planner_statuses(mission), timeout=1.0)
                        )
                except zenoh.ZError:
                    return False

            t_status = _wait_for("pfp serve answers its status", first_status, 90, logs)
            with client(endpoint) as s:

                def in_force() -> bool:
                    w = _world(s, mission)
                    return (
                        w is not None
                        and "t1" in _threats(w)
                        and {"u1", "f1"} <= {u for u, g in _goals(w).items() if g is not None}
                    )

                t_force = _wait_for("the threat and both goals in force", in_force, 30, logs)
                w = _world(s, mission)
                assert w is not None and _goals(w).get("u2") is None, w  # deleted before it started
            print(
                f"in force {t_force - t_status:.2f} s after the first status; {Path('/proc/loadavg').read_text()}"
            )
            assert t_force - t_status <= 2.0
            _wait_for("inject ends once its writes are taken", lambda: inject.poll() is not None, 30, logs)
        out = _text(ilog)
        # a writer says it waits once a write is 0.5 s unanswered, and then says when a planner took it;
        # a planner that starts within that half second takes the writes before there is anything to say
        if "waiting for a planner of mission" in out:
            assert "threat t1 taken by planner" in out, out
        assert inject.returncode == 0, out
        if "waiting for a planner of mission" in _text(flog):
            assert "goal f1 taken by planner" in _text(flog), _text(flog)


@pytest.mark.proc
def test_a_delete_is_never_undone_by_an_older_put_asked_again_by_another_writer(tmp_path):
    """Writer A puts, writer B deletes later, while no planner runs.

    Once one starts, both writers ask again in whatever order: the delete, newer, stays in force.
    """
    mission = "o" + uuid.uuid4().hex[:8]
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    goal = encode(Goal(position=(3.0, 4.0)))
    with _router(endpoint), client(endpoint) as sa, client(endpoint) as sb:
        a, b = Deliverer(sa, mission, retry_s=0.3), Deliverer(sb, mission, retry_s=0.2)
        try:
            a.put(keys.unit_goal(mission, "g1"), goal)
            a.put(
                keys.threat(mission, "x1"),
                encode(ThreatUpdate(position=(1.0, 1.0), sigma_range=1.0, sigma_lateral=0.7)),
            )
            time.sleep(0.05)  # B's clock is later
            b.delete(keys.unit_goal(mission, "g1"))
            b.put(keys.unit_goal(mission, "g2"), goal)
            assert not a.wait_delivered(1.0) and set(b.pending()) == {
                keys.unit_goal(mission, "g1"),
                keys.unit_goal(mission, "g2"),
            }
            with _pfp(
                "serve", "--mode", "client", "--connect", endpoint, "--mission", mission,
                "--state-dir", str(tmp_path / "s"),
            ) as (_p, slog):  # fmt: skip
                _wait_for(
                    "both writers' writes taken", lambda: not a.pending() and not b.pending(), 90, [slog]
                )
                w = _world(sa, mission)
                assert w is not None, _text(slog)
                goals = _goals(w)
                assert goals.get("g1") is None and goals.get("g2") == [3.0, 4.0], w
                assert _threats(w) == {"x1"}
        finally:
            a.close()
            b.close()


@pytest.mark.proc
def test_a_write_while_the_planner_restarts_is_in_force_after_and_an_acknowledged_delete_stays_deleted(
    tmp_path,
):
    """Durable state holds what was acknowledged; nothing a writer acknowledged is asked again to undo it."""
    mission = "r" + uuid.uuid4().hex[:8]
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    serve = ("serve", "--mode", "client", "--connect", endpoint, "--mission", mission)
    state = ("--state-dir", str(tmp_path / "state"))
    goal = encode(Goal(position=(3.0, 4.0)))
    with _router(endpoint), client(endpoint) as s:
        writer = Deliverer(s, mission, retry_s=0.3)
        try:
            with _pfp(*serve, *state) as (first, log):
                writer.put(keys.unit_goal(mission, "kept"), goal)
                writer.put(keys.unit_goal(mission, "gone"), goal)
                _wait_for("the first planner takes both goals", lambda: not writer.pending(), 90, [log])
                writer.delete(keys.unit_goal(mission, "gone"))
                _wait_for("it takes the delete", lambda: not writer.pending(), 30, [log])
                first.kill()  # no clean stop: only what it committed survives
                first.wait(timeout=10)
            writer.put(keys.unit_goal(mission, "late"), goal)  # while no planner runs
            assert not writer.wait_delivered(1.0)
            with _pfp(*serve, *state) as (_second, log2):
                _wait_for(
                    "the restarted planner takes the late goal", lambda: not writer.pending(), 90, [log2]
                )
                w = _world(s, mission)
                assert w is not None, _text(log2)
                goals = _goals(w)
                assert goals.get("kept") == [3.0, 4.0] and goals.get("late") == [3.0, 4.0], w
                assert goals.get("gone") is None, w
        finally:
            writer.close()
