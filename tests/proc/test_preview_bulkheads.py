"""Previews that cannot exhaust the host: admission, deadlines that end the work, killable bounded workers.

Unit tier: ``preview.admit`` refuses, naming the field, what is out of
proportion before any work; ``measure`` checks its deadline.  Proc tier: the
``WorkerPool`` kills a task past its budget (its slot serves the next one),
answers a task past its memory limit and replaces the worker, and its workers
ignore SIGINT; a real ``pfp serve`` answers the issue's preview bombs at once
and a plain preview after them, and a Ctrl-C to its process group prints no
traceback from any worker.
"""

from __future__ import annotations

import json
import math
import os
import queue
import signal
import subprocess
import sys
import tempfile
import threading
import time
from typing import Any

import numpy as np
import pytest

from pfp_service.core import ThreatField
from pfp_service.core.metrics import MEASURE_CHUNK, Epoch, measure
from pfp_service.errors import DeadlinePassed, InputError
from pfp_service.node.tasks import Outcome, Task
from pfp_service.node.workers import WorkerPool
from pfp_service.wire import Goal, ThreatUpdate, UnitState, decode_preview_request, keys
from pfp_service.world import translate
from pfp_service.world.events import GoalSet, StateReported, ThreatPut, WorldSettings
from pfp_service.world.preview import MAX_PREVIEW_WHATIFS, admit, preview
from pfp_service.world.world import World
from tests.conftest import ROOT
from tests.zenoh_util import client, free_port, planner_process, wait_for_planner

CAP = 200_000


def _world() -> World:
    w = World(WorldSettings(deliberation="inline"))
    w.apply(
        [
            ThreatPut("t1", ThreatUpdate(position=(40.0, 60.0), sigma_range=10.0, sigma_lateral=7.0)),
            StateReported("u", UnitState(position=(0.0, 0.0))),
            GoalSet("u", Goal(position=(100.0, 100.0))),
        ],
        0.0,
    )
    return w


def _admit(body: dict[str, Any]) -> Any:
    return admit(_world().view("u"), decode_preview_request(json.dumps(body).encode()), CAP)


def _threat(i: int, sigma: float) -> dict[str, Any]:
    return {"id": f"w{i}", "position": [10.0 * i, 5.0], "sigma_range": sigma, "sigma_lateral": sigma}


# -- admission (unit) -------------------------------------------------------------------------
@pytest.mark.unit
def test_the_issues_bomb_is_refused_before_any_work_naming_its_step():
    body = {"start": [-900, -900], "goal": [1e9, 1e9], "step": 1e-3, "max_iter": 10_000_000}
    with pytest.raises(InputError) as got:
        _admit(body | {"threats": [_threat(i, 1e6 if i % 2 else 5.0) for i in range(MAX_PREVIEW_WHATIFS)]})
    assert got.value.path == "$.step"
    assert str(CAP) in got.value.reason


@pytest.mark.unit
def test_too_many_what_ifs_are_refused_naming_the_threats():
    with pytest.raises(InputError) as got:
        _admit({"threats": [_threat(i, 5.0) for i in range(MAX_PREVIEW_WHATIFS + 1)]})
    assert got.value.path == "$.threats"


@pytest.mark.unit
def test_a_what_if_so_wide_its_escape_route_passes_the_cap_is_refused_naming_it():
    with pytest.raises(InputError) as got:
        _admit(
            {"start": [0, 0], "goal": [50, 50], "step": 0.01, "threats": [_threat(0, 5.0), _threat(1, 1e5)]}
        )
    assert got.value.path == "$.threats[1].sigma_range"


@pytest.mark.unit
def test_ordinary_previews_are_admitted_light_and_a_long_walk_heavy():
    plain = _admit({})
    assert not plain.heavy
    light = _admit({"threats": [_threat(0, 15.0)]})
    assert not light.heavy and light.whatifs == 1
    assert not _admit({"start": [0, 0], "goal": [565, 565], "threats": [_threat(0, 15.0)]}).heavy
    heavy = _admit({"start": [0, 0], "goal": [100, 100], "step": 0.001})  # 141,000 steps: under the cap
    assert heavy.heavy and heavy.steps == pytest.approx(100 * math.sqrt(2) / 0.001)


@pytest.mark.unit
def test_measuring_a_long_path_checks_its_deadline():
    field = ThreatField(
        tuple(
            translate.threat(
                ThreatUpdate(position=(float(i), 1.0), sigma_range=1.0, sigma_lateral=1.0), f"t{i}"
            )
            for i in range(50)
        ),
        "peak",
    )
    path = np.column_stack([np.linspace(0, 100, 3 * MEASURE_CHUNK), np.zeros(3 * MEASURE_CHUNK)])
    epochs = [Epoch(0, len(path) - 1, field)]
    asked = []

    def deadline() -> bool:
        asked.append(1)
        return len(asked) > 1  # passes at the second look (the first chunk is measured unasked)

    with pytest.raises(DeadlinePassed):
        measure(path, epochs, deadline)
    assert len(asked) == 2
    short = path[: MEASURE_CHUNK // 2]
    assert measure(short, [Epoch(0, len(short) - 1, field)], lambda: True).length > 0  # measured whole
    whole = measure(path, epochs)
    assert measure(path, epochs, lambda: False).exposure == pytest.approx(whole.exposure, rel=1e-12)


# -- the worker pool (proc: it starts worker processes) ------------------------------------------
def _run(
    pool: WorkerPool, task_fn: Any, args: tuple[Any, ...], budget_s: float = 5.0
) -> tuple[Outcome, float]:
    got: queue.Queue[Outcome] = queue.Queue()
    t0 = time.monotonic()
    pool.submit(Task(task_fn, args, got.put, budget_s=budget_s))
    out = got.get(timeout=60)
    return out, time.monotonic() - t0


@pytest.mark.proc
def test_a_task_past_its_budget_is_killed_and_its_slot_serves_the_next():
    pool = WorkerPool("t", 1, memory_mb=256)
    try:
        assert pool.wait_ready(60)
        first = pool.pids()
        out, took = _run(pool, time.sleep, (30.0,), budget_s=0.3)
        assert out.kind == "killed" and took < 5.0
        out, _ = _run(pool, math.hypot, (3.0, 4.0))
        assert out == Outcome("done", 5.0, "", out.run_s)
        assert pool.pids() and pool.pids() != first and pool.replaced == 1
        out, _ = _run(pool, math.sqrt, (-1.0,))
        assert out.kind == "error" and "ValueError" in out.detail
    finally:
        pool.shutdown()


@pytest.mark.proc
def test_a_task_past_the_memory_limit_is_answered_and_its_worker_replaced():
    pool = WorkerPool("t", 1, memory_mb=256)
    try:
        assert pool.wait_ready(60)
        first = pool.pids()
        out, _ = _run(pool, bytearray, (2 * 1024**3,))  # 2 GB: past the worker's limit, not the host's
        assert out.kind == "memory"
        out, _ = _run(pool, math.hypot, (3.0, 4.0))
        assert out.kind == "done" and pool.pids() != first
    finally:
        pool.shutdown()


@pytest.mark.proc
def test_workers_ignore_sigint_and_die_with_the_pool():
    pool = WorkerPool("t", 2, spare=True)
    try:
        assert pool.wait_ready(60)
        deadline = time.monotonic() + 30
        while len(pool.pids()) < 3:  # the two workers and the spare
            assert time.monotonic() < deadline
            time.sleep(0.05)
        pids = pool.pids()
        for pid in pids:
            os.kill(pid, signal.SIGINT)
        out, _ = _run(pool, math.hypot, (3.0, 4.0))
        assert out.kind == "done" and pool.pids() == pids and pool.replaced == 0
    finally:
        pool.shutdown()
    for pid in pids:
        with pytest.raises(ChildProcessError):
            os.waitpid(pid, os.WNOHANG)  # reaped: gone


# -- a real planner (proc) -----------------------------------------------------------------------
def _query(session: Any, body: bytes | None, timeout_s: float = 10.0) -> tuple[float, Any]:
    t0 = time.monotonic()
    replies = list(session.get(keys.preview("default", "u1"), payload=body, timeout=timeout_s))
    took = time.monotonic() - t0
    assert replies, "no answer"
    r = replies[0]
    return took, (
        json.loads(r.ok.payload.to_bytes()) if r.ok is not None else json.loads(r.err.payload.to_bytes())
    )


@pytest.mark.proc
def test_pfp_serve_answers_the_preview_bombs_at_once_and_plans_after_them():
    bomb = {
        "start": [-900, -900],
        "goal": [1e9, 1e9],
        "step": 1e-3,
        "max_iter": 10_000_000,
        "threats": [_threat(i, 1e6 if i % 2 else 5.0) for i in range(256)],
    }
    with planner_process() as (endpoint, _proc), client(endpoint) as s:
        answers: list[tuple[float, Any]] = []
        threads = [
            threading.Thread(target=lambda: answers.append(_query(s, json.dumps(bomb).encode())))
            for _ in range(3)
        ]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert len(answers) == 3
        for took, reply in answers:
            assert took < 5.0 and reply["field"] in ("$.step", "$.threats"), reply
        took, plan = _query(s, json.dumps({"start": [0, 0], "goal": [100, 100]}).encode())
        assert took < 3.0 and plan["status"] == "reached"


@pytest.mark.proc
def test_a_long_walk_ends_at_its_budget_and_the_next_preview_is_served():
    with planner_process("--preview-budget-ms", "300") as (endpoint, _proc), client(endpoint) as s:
        body = {"start": [0, 0], "goal": [134, 134], "step": 1e-3, "max_iter": 10_000_000}  # 190,000 steps
        took, reply = _query(s, json.dumps(body).encode())
        assert took < 5.0, reply  # its budget, the alarm past it, the kill past that: well within 5 s
        assert reply.get("status") == "max_iter" or reply.get("error", "").startswith("expired"), reply
        took, plan = _query(s, json.dumps({"start": [0, 0], "goal": [100, 100]}).encode())
        assert took < 3.0 and plan.get("status") == "reached", plan


@pytest.mark.proc
def test_ctrl_c_to_the_process_group_prints_no_traceback_from_any_worker():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with tempfile.TemporaryFile("w+") as log:
        proc = subprocess.Popen(
            [sys.executable, "-m", "pfp_service", "serve", "--listen", endpoint, "--state-dir", "none"],
            cwd=ROOT,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
            stdout=log,
            stderr=subprocess.STDOUT,
            text=True,
            start_new_session=True,  # its own process group, as a terminal gives it
        )
        try:
            wait_for_planner(endpoint, "default")
            with client(endpoint) as s:  # a worker killed and replaced: its successor starts meanwhile
                _query(s, json.dumps({"start": [0, 0], "goal": [134, 134], "step": 1e-3}).encode())
            os.killpg(proc.pid, signal.SIGINT)
            assert proc.wait(timeout=30) == 130
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        log.seek(0)
        text = log.read()
    assert "Traceback" not in text and "KeyboardInterrupt" not in text, text[-3000:]


@pytest.mark.unit
def test_a_what_if_reuses_the_worlds_packed_field_and_plans_the_same():
    w = _world()
    view = w.view("u")
    base = ThreatField(view.threats, "peak")
    extra = translate.threat(ThreatUpdate(position=(60.0, 50.0), sigma_range=8.0, sigma_lateral=5.0), "w1")
    replaced = translate.threat(ThreatUpdate(position=(30.0, 30.0), sigma_range=4.0, sigma_lateral=4.0), "t1")
    got = base.plus([extra, replaced], {"t1"})
    fresh = ThreatField((extra, replaced), "peak")
    assert got.threats == fresh.threats and np.array_equal(got.packed, fresh.packed)
    body = json.dumps(
        {"threats": [{"id": "w1", "position": [60.0, 50.0], "sigma_range": 8.0, "sigma_lateral": 5.0}]}
    )
    request = decode_preview_request(body.encode())
    shared = preview(w.view("u"), request, time.monotonic, 5.0, CAP, base)
    alone = preview(w.view("u"), request, time.monotonic, 5.0, CAP)
    assert shared.path == alone.path and shared.exposure == alone.exposure


@pytest.mark.proc
def test_a_burst_past_what_the_workers_can_start_is_answered_busy_at_once_not_queued_to_expiry():
    goal = [565.0, 565.0]
    bodies = [
        json.dumps({"start": [0, 0], "goal": goal, "threats": [_threat(0, 15.0 + i % 7)]}).encode()
        for i in range(60)
    ]
    with planner_process("--preview-wait-ms", "300") as (endpoint, _proc), client(endpoint) as s:
        answers: list[tuple[float, Any]] = []
        lock = threading.Lock()

        def one(body: bytes) -> None:
            got = _query(s, body)
            with lock:
                answers.append(got)

        threads = [threading.Thread(target=one, args=(b,)) for b in bodies]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    assert len(answers) == len(bodies)
    plans = [r for _, r in answers if "status" in r]
    busy = [(took, r) for took, r in answers if r.get("error", "").startswith("busy:")]
    # a preview that started but ran its whole budget (a loaded machine) is "expired ... stopped";
    # none waits in a queue until it expires ("deadline passed before it was computed")
    stopped = [r for _, r in answers if r.get("error", "").startswith("expired: the preview's budget")]
    assert plans and len(plans) + len(busy) + len(stopped) == len(answers), answers
    assert all("retry in" in r["error"] and took < 0.3 + 1.5 for took, r in busy)
    assert max(took for took, _ in answers) < 5.0
