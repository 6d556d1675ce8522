"""Scale-out: several --cluster planners share one mission, each unit guided by exactly one, with failover."""

from __future__ import annotations

import collections
import json
import queue
import signal
import subprocess
import sys
import time
import uuid

import zenoh

from tests.zenoh_util import ROOT, client, free_port, put_json

N_UNITS = 90
T = {"facing_deg": 225, "sigma_range": 1.0, "sigma_lateral": 0.7, "skew": 2}


def _router(endpoint: str) -> zenoh.Session:
    conf = zenoh.Config()
    conf.insert_json5("mode", '"router"')
    conf.insert_json5("listen/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(conf)


def _planner(endpoint: str, mission: str, pid: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "pfp_service", "serve", "--mode", "client", "--connect", endpoint,
         "--mission", mission, "--planner-id", pid, "--cluster", "--state-dir", "none",
         "--intensity", "density", "--delta", "0.08"],
        cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, text=True,
    )  # fmt: skip


def _wait_status(s: zenoh.Session, mission: str, pid: str, timeout: float = 90.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for r in s.get(f"mumt/{mission}/planner/{pid}/status", timeout=1.0):
            if r.ok is not None:
                return
        time.sleep(0.2)
    raise TimeoutError(f"planner {pid} never answered")


class Fleet:
    """Every unit reports in rounds; one wildcard subscriber records who answered what."""

    def __init__(self, s: zenoh.Session, mission: str) -> None:
        self.s, self.m = s, mission
        self.q: queue.Queue[tuple[float, dict]] = queue.Queue()
        self.sub = s.declare_subscriber(
            f"mumt/{mission}/unit/*/direction",
            lambda x: self.q.put((time.monotonic(), json.loads(x.payload.to_bytes()))),
        )
        self.units = [f"u{i:03d}" for i in range(N_UNITS)]
        self.seq = 0
        time.sleep(0.3)

    def rounds(self, n: int = 3, wait: float = 1.5) -> dict[str, set[str]]:
        """``n`` rounds, merged: a state or a direction dropped in a burst is made good by the next round."""
        merged: dict[str, set[str]] = collections.defaultdict(set)
        statuses: dict[str, str] = {}
        for _ in range(n):
            for u, p in self.round(wait).items():
                merged[u] |= p
            statuses.update(self.statuses)
        self.statuses = statuses
        return merged

    def round(self, wait: float = 1.0) -> dict[str, set[str]]:
        """One report from every unit; who answered each (by the planner id in the direction)."""
        self.seq += 1
        for i, u in enumerate(self.units):
            put_json(
                self.s,
                f"mumt/{self.m}/unit/{u}/state",
                {"position": [0.05 * (i % 10), 0.05 * (i // 10)], "seq": self.seq},
            )
        answered: dict[str, set[str]] = collections.defaultdict(set)
        self.statuses: dict[str, str] = {}
        deadline = time.monotonic() + wait
        while time.monotonic() < deadline:
            try:
                _, d = self.q.get(timeout=0.05)
            except queue.Empty:
                continue
            if d.get("seq") == self.seq:
                answered[d["unit"]].add(d["planner"])
                self.statuses[d["unit"]] = d["status"]
        return answered


def test_three_planners_share_the_fleet_and_take_over_a_killed_ones_units():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    mission = "c" + uuid.uuid4().hex[:8]
    procs: dict[str, subprocess.Popen[str]] = {}
    with _router(endpoint), client(endpoint) as s:
        try:
            for pid in ("p0", "p1", "p2"):
                procs[pid] = _planner(endpoint, mission, pid)
            for pid in procs:
                _wait_status(s, mission, pid)
            put_json(s, f"mumt/{mission}/threat/e1", {"position": [4, 6], **T})
            put_json(s, f"mumt/{mission}/threat/e2", {"position": [7, 3], **T})
            fleet = Fleet(s, mission)
            fleet.round()  # every unit is known
            for u in fleet.units:
                put_json(s, f"mumt/{mission}/unit/{u}/goal", {"position": [10, 10]})
            time.sleep(1.0)
            answered = fleet.rounds()
            # every unit is answered by exactly one planner, and the three share the fleet
            owned = {}
            for r in s.get(f"mumt/{mission}/planner/*/status", timeout=2):
                st = json.loads(r.ok.payload.to_bytes())
                owned[st["planner"]] = st["units_owned"]
            assert set(answered) == set(fleet.units), (set(fleet.units) - set(answered), owned)
            assert all(len(p) == 1 for p in answered.values()), {
                u: p for u, p in answered.items() if len(p) != 1
            }
            owner = {u: next(iter(p)) for u, p in answered.items()}
            load = collections.Counter(owner.values())
            assert set(load) == {"p0", "p1", "p2"} and min(load.values()) >= N_UNITS // 6, load
            assert set(fleet.statuses.values()) == {"en_route"}

            # SIGKILL one: its units are answered by the others, soon
            victims = {u for u, p in owner.items() if p == "p0"}
            procs["p0"].send_signal(signal.SIGKILL)
            procs["p0"].wait(timeout=10)
            killed = time.monotonic()
            taken: dict[str, float] = {}
            while len(taken) < len(victims) and time.monotonic() - killed < 15:
                for u, p in fleet.round(wait=0.3).items():
                    if u in victims and u not in taken and p - {"p0"}:
                        taken[u] = time.monotonic() - killed
            assert set(taken) == victims, victims - set(taken)
            assert max(taken.values()) <= 3.0 + 0.5, sorted(taken.values())[-3:]  # one round of slack
            # settled: exactly one planner each, every unit still on its goal
            answered = fleet.rounds()
            assert set(answered) == set(fleet.units)
            assert all(len(p) == 1 and "p0" not in p for p in answered.values())
            assert set(fleet.statuses.values()) == {"en_route"}, collections.Counter(fleet.statuses.values())

            # a planner started late knows the threats and goals at once and takes its share
            procs["p3"] = _planner(endpoint, mission, "p3")
            _wait_status(s, mission, "p3")
            time.sleep(1.0)
            answered = fleet.rounds()
            assert all(len(p) == 1 for p in answered.values()), {
                u: p for u, p in answered.items() if len(p) != 1
            }
            mine = [u for u, p in answered.items() if p == {"p3"}]
            assert mine and all(fleet.statuses[u] == "en_route" for u in mine)
        finally:
            for p in procs.values():
                if p.poll() is None:
                    p.terminate()
            for p in procs.values():
                try:
                    p.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    p.kill()
