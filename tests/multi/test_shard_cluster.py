"""State shards under --cluster: each planner receives only its own shards' states, and failover moves shards.

Real planner processes on loopback (tier multi).  The units publish on the
shard key (``keys.shard_state``), as pfp fleet and the handheld do; one more
unit publishes on the plain key, as an outside client may, and is still guided.
"""

from __future__ import annotations

import collections
import json
import queue
import signal
import subprocess
import time
import uuid

import pytest
import zenoh

from pfp_service.wire import keys
from tests.multi.test_cluster import _planner, _put_reliably, _router, _wait_status, _world
from tests.zenoh_util import client, free_port, put_json

pytestmark = [pytest.mark.multi, pytest.mark.alone]

UNITS = [f"s{i:03d}" for i in range(200)]
PLAIN = "outside-1"  # publishes on mumt/{m}/unit/{u}/state
ROUNDS = 4


def _status(s: zenoh.Session, mission: str, pid: str) -> dict[str, object]:
    (r,) = [r for r in s.get(keys.planner_status(mission, pid), timeout=3.0) if r.ok is not None]
    return dict(json.loads(r.ok.payload.to_bytes()))


def _round(s: zenoh.Session, mission: str, seq: int, q: queue.Queue, wait: float) -> dict[str, set[str]]:
    for i, u in enumerate(UNITS):
        put_json(
            s, keys.shard_state(mission, u), {"position": [0.02 * (i % 20), 0.02 * (i // 20)], "seq": seq}
        )
    put_json(s, keys.unit_state(mission, PLAIN), {"position": [0.1, 0.1], "seq": seq})
    got: dict[str, set[str]] = collections.defaultdict(set)
    deadline = time.monotonic() + wait
    while time.monotonic() < deadline:
        try:
            d = q.get(timeout=0.05)
        except queue.Empty:
            continue
        if d.get("seq") == seq:
            got[d["unit"]].add(d["planner"])
    return got


def test_two_planners_each_receive_their_shards_and_one_takes_over_the_others():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    mission = "sh" + uuid.uuid4().hex[:8]
    procs: dict[str, subprocess.Popen[str]] = {}
    with _router(endpoint), client(endpoint) as s:
        try:
            for pid in ("pa", "pb"):
                procs[pid] = _planner(endpoint, mission, pid)
            for pid in procs:
                _wait_status(s, mission, pid)
            q: queue.Queue[dict] = queue.Queue()
            _sub = s.declare_subscriber(
                keys.unit_directions(mission), lambda x: q.put(json.loads(x.payload.to_bytes()))
            )
            time.sleep(1.0)  # each planner has seen the other's token and taken its shards
            _round(s, mission, 1, q, 2.0)  # every unit known
            for u in [*UNITS, PLAIN]:
                _put_reliably(s, keys.unit_goal(mission, u), {"position": [10.0, 10.0]})
            time.sleep(2.0)
            before = {p: int(_status(s, mission, p)["msgs_in"]) for p in procs}  # type: ignore[call-overload]
            merged: dict[str, set[str]] = collections.defaultdict(set)
            for seq in range(2, 2 + ROUNDS):
                for u, ps in _round(s, mission, seq, q, 1.5).items():
                    merged[u] |= ps
            got = {p: int(_status(s, mission, p)["msgs_in"]) - before[p] for p in procs}  # type: ignore[call-overload]
            assert set(merged) >= {*UNITS, PLAIN}, sorted({*UNITS, PLAIN} - set(merged))[:10]
            assert all(len(ps) == 1 for ps in merged.values()), {
                u: p for u, p in merged.items() if len(p) > 1
            }
            owner = {u: next(iter(ps)) for u, ps in merged.items()}
            for u in UNITS:  # the owner is its shard's: each planner decides alone, and they agree
                assert owner[u] == owner[UNITS[[keys.shard_of(v) for v in UNITS].index(keys.shard_of(u))]]
            sent = ROUNDS * len(UNITS)
            for p, n in got.items():  # about half the states each (msgs_in also counts peers' missions)
                assert n <= 0.7 * sent, (p, n, sent, got)
            for p in procs:  # what a planner heard lately is its own shards' units (and the plain-key one)
                units, _, _ = _world(s, mission, p)
                heard = {u for u, v in units.items() if v.last_seen_s is not None and v.last_seen_s < 30}  # type: ignore[attr-defined]
                mine = {u for u, o in owner.items() if o == p} | {PLAIN}
                assert heard - {PLAIN} and heard <= mine, (p, sorted(heard - mine)[:10])

            # SIGKILL one: the other takes its shards and guides its units
            victims = {u for u, p in owner.items() if p == "pa"}
            assert victims
            procs["pa"].send_signal(signal.SIGKILL)
            procs["pa"].wait(timeout=10)
            killed = time.monotonic()
            taken: dict[str, float] = {}
            seq = 100
            while len(taken) < len(victims) and time.monotonic() - killed < 30:
                seq += 1
                for u, ps in _round(s, mission, seq, q, 0.3).items():
                    if u in victims and "pb" in ps:
                        taken.setdefault(u, time.monotonic() - killed)
            assert set(taken) == victims, sorted(victims - set(taken))[:10]
            # killed: its token goes within ms, the debounce is 0.5 s, then the shards' rings; a round is 0.3 s
            assert max(taken.values()) <= 3.0 + 0.3, sorted(taken.values())[-5:]
        finally:
            for p in procs.values():
                if p.poll() is None:
                    p.send_signal(signal.SIGTERM)
            for p in procs.values():
                try:
                    p.wait(timeout=15)
                except subprocess.TimeoutExpired:
                    p.kill()
