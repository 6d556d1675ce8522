"""The loop's trace (``loopstats.LoopTrace``): a JSON line a second, off unless asked."""

from __future__ import annotations

import contextlib
import gc
import json
import os

import pytest
import zenoh

from pfp_service.node.loopstats import LoopTrace, demote_native_threads


class _Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


@pytest.mark.unit
def test_a_trace_writes_one_line_a_second_with_the_parts_states_and_collections(tmp_path):
    path = tmp_path / "loop.jsonl"
    clock = _Clock()
    trace = LoopTrace(str(path), clock)
    try:
        assert trace.on
        for i in range(10):  # 10 ticks over 0.9 s: no line yet
            clock.t += 0.1 if i else 0.0
            trace.part("apply", 0.002)
            trace.part("put", 0.001)
            trace.tick(0.004 if i == 3 else 0.003, 5, 0.006 if i == 3 else 0.002, clock.t)
        assert not path.exists()
        gc.collect()  # a full collection while tracing: counted as gen2
        clock.t += 0.2
        trace.tick(0.003, 7, 0.001, clock.t)
        (line,) = path.read_text().splitlines()
        got = json.loads(line)
        assert got["ticks"] == 11 and got["states"] == 57
        assert got["wall_max_ms"] == 4.0 and got["wait_max_ms"] == 6.0
        assert got["apply_ms"] == pytest.approx(20.0) and got["put_ms"] == pytest.approx(10.0)
        assert got["gc"]["gen2_n"] >= 1
        clock.t += 1.5  # the next second starts afresh
        trace.tick(0.001, 1, 0.0, clock.t)
        second = json.loads(path.read_text().splitlines()[1])
        assert second["ticks"] == 1 and second["states"] == 1 and "apply_ms" not in second
    finally:
        trace.close()
    assert trace._gc not in gc.callbacks


@pytest.mark.unit
def test_off_without_a_path_and_an_unwritable_file_turns_it_off(tmp_path):
    clock = _Clock()
    off = LoopTrace(None, clock)
    assert not off.on and off._gc not in gc.callbacks
    bad = LoopTrace(str(tmp_path / "no" / "such" / "dir.jsonl"), clock)
    assert bad.on
    clock.t += 2.0
    bad.tick(0.001, 1, 0.0, clock.t)  # the write fails: the trace stops, the caller goes on
    assert not bad.on and bad._gc not in gc.callbacks


@pytest.mark.net
@pytest.mark.skipif(not hasattr(os, "SCHED_BATCH"), reason="SCHED_BATCH is Linux's")
def test_zenohs_threads_go_under_sched_batch_and_pythons_keep_the_default():
    import threading

    from tests.zenoh_util import free_port

    conf = zenoh.Config()
    conf.insert_json5("listen/endpoints", json.dumps([f"tcp/127.0.0.1:{free_port()}"]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    stop = threading.Event()
    waiter = threading.Thread(target=stop.wait, name="pfp-test-waiter")
    waiter.start()
    session = zenoh.open(conf)
    try:
        demote_native_threads()
        python = {t.native_id for t in threading.enumerate()}
        native = [int(t) for t in os.listdir("/proc/self/task") if int(t) not in python]
        assert native, "a Zenoh session starts threads of its own"
        for tid in native:
            with contextlib.suppress(OSError):  # a thread that ended meanwhile
                assert os.sched_getscheduler(tid) == os.SCHED_BATCH, tid
        for tid in python:
            assert os.sched_getscheduler(tid) == os.SCHED_OTHER, tid
        assert demote_native_threads() == 0  # already moved: nothing more
    finally:
        session.close()
        stop.set()
        waiter.join()
