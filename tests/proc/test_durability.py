"""Durable state: goals, threats and missions survive a killed planner."""

from __future__ import annotations

import contextlib
import json
import math
import os
import queue
import signal
import subprocess
import sys
import threading
import time
import uuid

import pytest
import zenoh

from pfp_service.core import PlannerParams
from pfp_service.node.store import Store
from pfp_service.wire import Goal, ThreatUpdate, UnitState
from pfp_service.world.world import (
    GoalCancelled,
    GoalSet,
    MissionRestored,
    StateReported,
    ThreatPut,
    ThreatRemoved,
    World,
    WorldSettings,
)
from tests.zenoh_util import ROOT, Inbox, client, free_port, put_json, wait_for_planner

pytestmark = pytest.mark.proc

T = dict(facing_deg=225.0, sigma_range=1.0, sigma_lateral=0.7, skew=2.0)


def _world():
    return World(WorldSettings(planner=PlannerParams(intensity="density", delta=0.08)))


def test_store_restores_threats_with_the_time_left_goals_and_missions(tmp_path):
    store = Store(tmp_path / "s")
    batch = [
        ThreatPut("e1", ThreatUpdate(position=(4, 6), **T)),
        ThreatPut("short", ThreatUpdate(position=(7, 3), ttl_s=10.0, **T)),
        ThreatPut("gone", ThreatUpdate(position=(9, 9), **T)),
        ThreatRemoved("gone"),
        GoalSet("u", Goal(position=(10, 10))),
        GoalSet("v", Goal(position=(5, 5))),
        GoalCancelled("v"),
    ]
    store.commit_inputs(batch, wall_now=1000.0, default_ttl_s=None)
    w = _world()
    out = w.apply([*batch, StateReported("u", UnitState(position=(0.5, 0.0)))], 0.0)
    store.record_missions(out.missions)
    store.close()

    again = Store(tmp_path / "s").restore(wall_now=1004.0)
    assert (again.kept["threat"], again.kept["goal"], again.missions, again.expired) == (2, 1, 1, 0)
    puts = {i.threat: i.update for i in again.inputs if isinstance(i, ThreatPut)}
    assert set(puts) == {"e1", "short"} and math.isclose(puts["short"].ttl_s, 6.0)
    (mission,) = [i for i in again.inputs if isinstance(i, MissionRestored)]
    assert mission.origin == (0.5, 0.0) and mission.params == w.view("u").stepper.params
    assert Store(tmp_path / "s").restore(wall_now=1011.0).expired == 1


def test_a_restored_unit_moves_exactly_as_it_would_have(tmp_path):
    store = Store(tmp_path)
    live = _world()
    inputs = [
        ThreatPut("e1", ThreatUpdate(position=(4, 6), **T)),
        ThreatPut("e2", ThreatUpdate(position=(7, 3), **T)),
        GoalSet("u", Goal(position=(10, 10))),
    ]
    store.commit_inputs(inputs, 0.0, None)
    out = live.apply([*inputs, StateReported("u", UnitState(position=(0.0, 0.0)))], 0.0)
    store.record_missions(out.missions)
    step = live.view("u").stepper.params.step
    pos = (0.0, 0.0)
    for k in range(40):  # part way, then the planner dies
        (d,) = live.apply([StateReported("u", UnitState(position=pos))], float(k)).directions
        pos = (pos[0] + step * d.vector[0], pos[1] + step * d.vector[1])
    reborn = _world()
    reborn.apply(Store(tmp_path).restore(0.0).inputs, 0.0)
    # x0 and the parameters are the mission's, not re-derived from where the unit now is
    assert reborn.view("u").origin == (0.0, 0.0)
    (a,) = live.apply([StateReported("u", UnitState(position=pos))], 50.0).directions
    (b,) = reborn.apply([StateReported("u", UnitState(position=pos))], 50.0).directions
    assert a.vector == b.vector and a.status == b.status


def test_a_bad_state_dir_is_one_line_and_exit_2(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    r = subprocess.run(
        [sys.executable, "-m", "pfp_service", "serve", "--state-dir", str(blocker / "sub"), "--listen",
         f"tcp/127.0.0.1:{free_port()}"],
        capture_output=True, text=True, timeout=60, cwd=ROOT,
    )  # fmt: skip
    assert r.returncode == 2, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "--state-dir" in r.stderr


def _router(endpoint):
    conf = zenoh.Config()
    conf.insert_json5("mode", '"router"')
    conf.insert_json5("listen/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(conf)


def _planner(endpoint, mission, state_dir):
    return subprocess.Popen(
        [sys.executable, "-m", "pfp_service", "serve", "--mode", "client", "--connect", endpoint,
         "--mission", mission, "--state-dir", str(state_dir), "--intensity", "density", "--delta", "0.08"],
        cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, text=True,
    )  # fmt: skip


def test_kill_9_mid_mission_then_restart_and_every_unit_arrives(tmp_path):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    mission = "d" + uuid.uuid4().hex[:8]
    units = {"u1": (0.0, 0.0), "u2": (0.0, 1.0), "u3": (1.0, 0.0)}
    with _router(endpoint), client(endpoint) as s:
        proc = _planner(endpoint, mission, tmp_path)
        try:
            wait_for_planner(endpoint, mission)
            events = Inbox(s, f"mumt/{mission}/event/restored")
            inboxes = {u: Inbox(s, f"mumt/{mission}/unit/{u}/direction") for u in units}
            time.sleep(0.3)
            put_json(s, f"mumt/{mission}/threat/e1", {"position": [4, 6], **T})
            put_json(s, f"mumt/{mission}/threat/e2", {"position": [7, 3], **T})
            for u in units:
                put_json(s, f"mumt/{mission}/unit/{u}/goal", {"position": [10, 10]})
            pos = dict(units)
            seq = 0

            def drive(steps):
                nonlocal seq
                last = {}
                for _ in range(steps):
                    seq += 1
                    for u, p in pos.items():
                        if last.get(u) == "arrived":
                            continue
                        put_json(s, f"mumt/{mission}/unit/{u}/state", {"position": list(p), "seq": seq})
                    for u in pos:
                        if last.get(u) == "arrived":
                            continue
                        d = None
                        for _attempt in range(6):  # a state or its answer lost in transit: report again
                            try:
                                d = inboxes[u].get(where=lambda m, q=seq: m.get("seq") == q, timeout=10)
                                break
                            except TimeoutError:
                                put_json(
                                    s,
                                    f"mumt/{mission}/unit/{u}/state",
                                    {"position": list(pos[u]), "seq": seq},
                                )
                        assert d is not None, f"{u} got no answer to seq {seq}"
                        last[u] = d["status"]
                        if d["status"] in ("en_route", "escaping"):
                            step = 0.0667  # the planner's step for this scale; exactness is not the point
                            pos[u] = (pos[u][0] + step * d["vector"][0], pos[u][1] + step * d["vector"][1])
                    if all(v == "arrived" for v in last.values()) and len(last) == len(pos):
                        break
                return last

            first = drive(30)
            assert all(v == "en_route" for v in first.values()), first
            proc.send_signal(signal.SIGKILL)
            proc.wait(timeout=10)
            proc = _planner(endpoint, mission, tmp_path)
            wait_for_planner(endpoint, mission)
            restored = events.get(timeout=20)
            assert (restored["threats"], restored["goals"], restored["missions"]) == (2, 3, 3)
            last = drive(600)
            assert last == {u: "arrived" for u in units}, last
            for u, p in pos.items():
                assert math.dist(p, (10, 10)) < 0.2
        finally:
            proc.terminate()
            proc.wait(timeout=10)


def test_a_client_planner_waits_for_its_router(tmp_path):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    mission = "w" + uuid.uuid4().hex[:8]
    proc = subprocess.Popen(
        [sys.executable, "-m", "pfp_service", "serve", "--mode", "client", "--connect", endpoint,
         "--mission", mission, "--state-dir", "none"],
        cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    lines: queue.Queue[str] = queue.Queue()
    threading.Thread(target=lambda: [lines.put(x) for x in proc.stderr], daemon=True).start()  # type: ignore[union-attr]
    try:
        deadline = time.monotonic() + 60
        while True:  # it says it waits, and goes on waiting, rather than exiting
            line = lines.get(timeout=max(deadline - time.monotonic(), 0.1))
            if "waiting for the router" in line:
                break
        assert proc.poll() is None
        with _router(endpoint):
            wait_for_planner(endpoint, mission, timeout=30)
    finally:
        proc.terminate()
        proc.wait(timeout=10)
    assert proc.returncode == 0


def test_the_fleet_puts_its_goals_again_for_a_planner_that_lost_them(tmp_path):
    """Belt and braces: a planner restarted without durable state answers no_goal; the fleet re-puts."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    mission = "f" + uuid.uuid4().hex[:8]
    team = tmp_path / "team.yaml"
    team.write_text(
        "name: t\nunits:\n  - {id: r1, kind: unmanned, start: [0, 0], goal: [400, 0], speed_mps: 2}\n"
    )

    def planner():
        return subprocess.Popen(
            [sys.executable, "-m", "pfp_service", "serve", "--mode", "client", "--connect", endpoint,
             "--mission", mission, "--state-dir", "none"],
            cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, text=True,
        )  # fmt: skip

    with _router(endpoint):
        p = planner()
        wait_for_planner(endpoint, mission)
        fleet = subprocess.Popen(
            [sys.executable, "-m", "pfp_service", "fleet", "--team", str(team), "--connect", endpoint,
             "--mission", mission, "--rate-hz", "5", "--speed-up", "5", "--duration-s", "600"],
            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        )  # fmt: skip
        lines: queue.Queue[str] = queue.Queue()
        threading.Thread(target=lambda: [lines.put(x) for x in fleet.stdout], daemon=True).start()  # type: ignore[union-attr]
        try:
            time.sleep(3.0)
            p.send_signal(signal.SIGKILL)
            p.wait(timeout=10)
            p = planner()  # no durable state: it knows no goal
            deadline = time.monotonic() + 90
            seen = []
            while time.monotonic() < deadline:
                try:
                    line = lines.get(timeout=1.0)
                except queue.Empty:
                    continue
                seen.append(line)
                if "goal put again" in line:
                    break
            else:
                raise AssertionError("".join(seen[-20:]))
        finally:
            for proc in (fleet, p):
                proc.terminate()
                proc.wait(timeout=10)


def _children(pid: int) -> set[int]:
    """Every live process whose parent is ``pid`` (from /proc: no dependency for one test)."""
    import pathlib

    kids = set()
    for stat in pathlib.Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid and fields[0] != "Z":
            kids.add(int(stat.parent.name))
    return kids


def _alive(pid: int) -> bool:
    import pathlib

    try:
        return pathlib.Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def test_a_planner_killed_takes_its_worker_processes_with_it():
    """Preview and deliberation workers watch their planner: SIGKILL leaves no orphan running."""
    from pfp_service.wire import keys
    from tests.zenoh_util import client, planner_process

    with planner_process("--state-dir", "none", mission="orphans") as (endpoint, proc):
        # one preview worker starts with the planner; a first preview starts the second and the spare
        with client(endpoint) as s:
            list(
                s.get(
                    keys.preview("orphans", "u1"), payload=b'{"start": [0, 0], "goal": [50, 0]}', timeout=20
                )
            )
        deadline = time.monotonic() + 60
        workers: set[int] = set()
        while (
            time.monotonic() < deadline and len(workers) < 4
        ):  # the fork server, 2 preview workers, the spare
            workers = (
                set()
            )  # the workers are the fork server's children (forkserver.ForkServer), not the planner's
            todo = [proc.pid]
            while todo:
                todo += (kids := _children(todo.pop()))
                workers |= kids
            time.sleep(0.2)
        assert len(workers) >= 4, workers
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
        deadline = time.monotonic() + 15
        while time.monotonic() < deadline and any(_alive(w) for w in workers):
            time.sleep(0.2)
        left = [w for w in workers if _alive(w)]
        for w in left:  # never leave them behind, whatever the verdict
            with contextlib.suppress(OSError):
                os.kill(w, signal.SIGKILL)
        assert not left, f"workers still running after their planner was killed: {left}"
