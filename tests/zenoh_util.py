"""Helpers for network tests: free ports, client sessions, a planner subprocess, waiting on queues."""

from __future__ import annotations

import json
import os
import queue
import socket
import subprocess
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import zenoh

ROOT = Path(__file__).resolve().parent.parent


# Ports come from a block of this process's own, below Linux's ephemeral range (32768-60999), not from
# the kernel's port 0: a port is free only until something binds it, so a kernel-picked port handed to a
# planner could meanwhile go to another xdist worker's planner, or to any outgoing connection on the
# machine.  Each worker (PYTEST_XDIST_WORKER gwN) owns block N, so two workers never pick one port, and
# a run starts at an offset of its own within its block, so two runs at once on one machine seldom meet.
_PORT_BASE, _PORT_BLOCK, _PORT_BLOCKS = 20000, 1500, 8


def _port_block() -> range:
    worker = os.environ.get("PYTEST_XDIST_WORKER", "gw0").removeprefix("gw")
    start = _PORT_BASE + (int(worker) % _PORT_BLOCKS if worker.isdigit() else 0) * _PORT_BLOCK
    return range(start, start + _PORT_BLOCK)


_ports = _port_block()
_next_port = [os.getpid() * 7919 % _PORT_BLOCK]


def free_port() -> int:
    """A loopback port no other worker of this run hands out, and free (TCP and UDP) when asked."""
    for _ in range(len(_ports)):
        port = _ports[_next_port[0] % len(_ports)]
        _next_port[0] += 1
        try:
            with socket.socket() as tcp, socket.socket(type=socket.SOCK_DGRAM) as udp:
                tcp.bind(("127.0.0.1", port))
                udp.bind(("127.0.0.1", port))
        except OSError:
            continue
        return port
    raise RuntimeError(f"no free port in {_ports}")


def client_config(endpoint: str) -> zenoh.Config:
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    return conf


@contextmanager
def client(endpoint: str):
    session = zenoh.open(client_config(endpoint))
    try:
        yield session
    finally:
        session.close()


class PlannerExited(RuntimeError):
    """A planner ``wait_for_planner`` waited for exited first."""


def wait_for_planner(
    endpoint: str, mission: str, timeout: float = 180.0, proc: subprocess.Popen | None = None, log: Any = None
) -> None:
    """Until the planner answers its status; a first start on a fresh checkout compiles its kernels (a minute of CPU).

    With ``proc``, a planner that exits meanwhile (its port taken, a bad flag) fails at once, with the
    end of its output (``log``, a file it writes to), not after ``timeout``.
    """
    deadline = time.monotonic() + timeout
    last: Exception | None = None

    def exited() -> None:
        if proc is not None and proc.poll() is not None:
            tail = ""
            if log is not None:
                log.flush()
                log.seek(0)
                tail = log.read()[-2000:]
            raise PlannerExited(
                f"planner on {endpoint} exited with {proc.returncode} before it answered:\n{tail}"
            )

    while time.monotonic() < deadline:
        exited()
        try:
            with client(endpoint) as s:
                while time.monotonic() < deadline:
                    for r in s.get(f"mumt/{mission}/planner/*/status", timeout=1.0):
                        if r.ok is not None:
                            return
                    exited()
                    time.sleep(0.1)
        except PlannerExited:
            raise
        except Exception as exc:  # router not listening yet
            last = exc
            time.sleep(0.2)
    raise TimeoutError(f"planner on {endpoint} did not answer: {last}")


@contextmanager
def planner_process(*extra: str, mission: str = "default"):
    """``pfp serve`` as a subprocess on a free loopback port; yields (endpoint, process)."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    # Output goes to a file, never a pipe nobody reads: a full pipe would block the planner's logging.
    log = tempfile.TemporaryFile("w+")  # noqa: SIM115 - closed in the finally below, after the process
    proc = subprocess.Popen(
        [sys.executable, "-m", "pfp_service", "serve", "--listen", endpoint, "--mission", mission, *extra],
        cwd=ROOT,
        env=env,
        stdout=log,
        stderr=subprocess.STDOUT,
        text=True,
    )
    proc.pfp_log = log  # type: ignore[attr-defined]  # a test may show what the planner said
    try:
        wait_for_planner(endpoint, mission, proc=proc, log=log)
        yield endpoint, proc
    finally:
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        log.close()


class Inbox:
    """A subscriber feeding a queue of decoded JSON payloads (or DELETE markers)."""

    def __init__(self, session: zenoh.Session, key: str) -> None:
        self.q: queue.Queue[tuple[str, Any]] = queue.Queue()
        self.sub = session.declare_subscriber(key, self._cb)

    def _cb(self, sample: zenoh.Sample) -> None:
        data = sample.payload.to_bytes()
        self.q.put((str(sample.key_expr), json.loads(data) if data else None))

    def get(self, timeout: float = 5.0, where=lambda msg: True) -> Any:
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError("no matching message")
            try:
                _key, msg = self.q.get(timeout=left)
            except queue.Empty:
                raise TimeoutError("no matching message") from None
            if where(msg):
                return msg


def guide_in_a_column(
    session: zenoh.Session, mission: str, ids: list[str], inbox: Inbox, timeout: float = 60.0
) -> set[str]:
    """Report unit ``ids[i]`` at ``(0, i)`` (their goals put already), again until each has had a moving
    direction (``inbox`` hears the directions) or ``timeout`` passes; the units that had one."""
    from pfp_service.wire import keys

    answered: set[str] = set()
    deadline = time.monotonic() + timeout
    seq = 0
    while answered != set(ids) and time.monotonic() < deadline:
        seq += 1
        for i, u in enumerate(ids):
            put_json(session, keys.shard_state(mission, u), {"position": [0.0, float(i)], "seq": seq})
        while answered != set(ids):  # until every unit or a second without a direction
            try:
                d = inbox.get(timeout=1.0)
            except TimeoutError:
                break
            if d["status"] in ("en_route", "escaping"):
                answered.add(d["unit"])
    return answered


def put_json(session: zenoh.Session, key: str, obj: Any) -> None:
    session.put(key, json.dumps(obj).encode(), encoding=zenoh.Encoding.APPLICATION_JSON)


def put_in_force(session: zenoh.Session, mission: str, writes: dict[str, Any], timeout: float = 15.0) -> None:
    """Put goals and threats as the clients do (acknowledged writes), and return once a planner applied them.

    A plain put races the unit states that follow it: each subscriber has its own
    callback thread, so a state can reach the planner's tick before the goal put
    just before it.  A test that needs the goal in force first waits for the ack.
    """
    from pfp_service.wire.delivery import Deliverer

    with Deliverer(session, mission) as d:
        for key, obj in writes.items():
            d.put(key, json.dumps(obj).encode())
        if not d.wait_delivered(timeout):
            raise TimeoutError(f"no planner acknowledged {d.pending()}")
