"""Access control: routers started from ``pfp acl`` output deny what issue 11 saw done, and allow the real flows.

Each test talks to a Python router opened from the generated config itself
(user/password, or mutual TLS with certificates from ``docker/gen-certs.py``).
"Denied" is shown by a legitimate message sent after the hostile one arriving
while the hostile one never does.
"""

from __future__ import annotations

import json
import queue
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import pytest
import zenoh

from pfp_service.cli import main as pfp_main
from tests.zenoh_util import ROOT, Inbox, free_port, put_json

pytestmark = pytest.mark.proc

M = "acl"
UNITS = ("u1", "u2")
GEN_CERTS = ROOT / "docker" / "gen-certs.py"
TEAM = """name: acl-test
units:
  - {id: u1, start: [0, 0], goal: [10, 10]}
  - {id: u2, start: [0, 5], goal: [10, 10]}
"""
NOT_DELIVERED_S = 0.6  # after the legitimate message arrived, how long we still watch for the hostile one


def _generate(tmp: Path, port: int, tls: bool) -> Path:
    team = tmp / "team.yaml"
    team.write_text(TEAM)
    out = tmp / "acl"
    scheme = "tls" if tls else "tcp"
    argv = ["acl", str(team), "--out", str(out), "--mission", M, "--quiet"]
    argv += ["--listen", f"tcp/127.0.0.1:{port}", "--connect-host", f"127.0.0.1:{port}"]
    assert pfp_main([*argv, "--tls"] if tls else argv) == 0, scheme
    if tls:
        done = subprocess.run(
            [sys.executable, str(GEN_CERTS), "--out", str(out), "--names-file", str(out / "names.txt")],
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert done.returncode == 0, done.stderr
    return out


class Router:
    """A router opened from the generated config, and sessions opened as its principals."""

    def __init__(self, out: Path, port: int, tls: bool) -> None:
        self.out, self.port, self.tls = out, port, tls
        conf = zenoh.Config.from_file(str(out / ("zenoh-router-mtls.json5" if tls else "zenoh-router.json5")))
        self.session = zenoh.open(conf)

    def config_of(self, name: str) -> zenoh.Config:
        return zenoh.Config.from_file(str(self.out / "clients" / f"{name}{'-tls' if self.tls else ''}.json5"))

    @contextmanager
    def as_(self, name: str):
        s = zenoh.open(self.config_of(name))
        try:
            yield s
        finally:
            s.close()


@pytest.fixture(scope="module", params=["usrpwd", "mtls"])
def router(request, tmp_path_factory):
    tls = request.param == "mtls"
    port = free_port()
    out = _generate(tmp_path_factory.mktemp(request.param), port, tls)
    r = Router(out, port, tls)
    try:
        yield r
    finally:
        r.session.close()


def _settle() -> None:
    time.sleep(0.3)  # declarations reach the router; nothing here waits on data with it


def _drain(inbox: Inbox) -> list:
    out = []
    while True:
        try:
            out.append(inbox.q.get_nowait()[1])
        except queue.Empty:
            return out


def _denied(inbox: Inbox, legit, hostile, is_hostile, what: str, timeout: float = 10.0) -> None:
    """``hostile()`` is dropped by the router while ``legit()`` gets through on the same path.

    The path is proved first (``legit`` repeated until it arrives: the subscription is in
    place), then ``hostile`` and ``legit`` are sent once more and every sample is kept
    until the second legitimate one and ``NOT_DELIVERED_S`` after it.
    """
    deadline = time.monotonic() + timeout
    while True:
        legit()
        try:
            inbox.get(timeout=0.5)
            break
        except TimeoutError:
            assert time.monotonic() < deadline, f"the legitimate path never carried anything ({what})"
    time.sleep(0.1)
    _drain(inbox)
    hostile()
    legit()
    seen = [inbox.get(timeout=timeout)]
    while not any(not is_hostile(m) for m in seen):
        seen.append(inbox.get(timeout=timeout))
    time.sleep(NOT_DELIVERED_S)
    seen += _drain(inbox)
    assert not [m for m in seen if is_hostile(m)], f"{what} was delivered: {seen}"


def _answers(session: zenoh.Session, selector: str, timeout: float = 10.0) -> list:
    """The decoded ok replies to ``selector``, asking again until there is one (a new queryable propagates)."""
    deadline = time.monotonic() + timeout
    while True:
        got = [json.loads(r.ok.payload.to_bytes()) for r in session.get(selector, timeout=2.0) if r.ok]
        if got or time.monotonic() > deadline:
            return got
        time.sleep(0.1)


def _never(inbox: Inbox, what: str, where=lambda msg: True) -> None:
    with pytest.raises(TimeoutError):
        got = inbox.get(timeout=NOT_DELIVERED_S, where=where)
        pytest.fail(f"{what} was delivered: {got}")


STATE = {"position": [1.0, 2.0], "seq": 1}
THREAT = {"position": [5, 5], "sigma_range": 1.0, "sigma_lateral": 1.0}
DIRECTION = {"unit": "u1", "status": "en_route", "vector": [1.0, 0.0]}


# -- denied -------------------------------------------------------------------------
def test_a_unit_cannot_spoof_another_units_state(router):
    with router.as_("observer") as obs, router.as_("unit-u1") as u1, router.as_("unit-u2") as u2:
        inbox = Inbox(obs, f"mumt/{M}/unit/*/state")
        _denied(
            inbox,
            lambda: put_json(u1, f"mumt/{M}/unit/u1/state", STATE),
            lambda: put_json(u2, f"mumt/{M}/unit/u1/state", {**STATE, "seq": 666}),
            lambda m: m["seq"] == 666,
            "u2's state for u1",
        )


def test_a_unit_cannot_set_another_units_goal(router):
    with router.as_("observer") as obs, router.as_("unit-u2") as u2, router.as_("commander") as cmd:
        inbox = Inbox(obs, f"mumt/{M}/unit/*/goal")

        def spoof() -> None:
            put_json(u2, f"mumt/{M}/unit/u1/goal", {"position": [999, 999]})
            u2.delete(f"mumt/{M}/unit/u1/goal")  # a DELETE arrives as None

        _denied(
            inbox,
            lambda: put_json(cmd, f"mumt/{M}/unit/u1/goal", {"position": [10, 10]}),
            spoof,
            lambda m: m != {"position": [10, 10]},
            "u2's goal for u1",
        )


@pytest.mark.parametrize("who", ["unit-u1", "commander", "observer"])
def test_only_a_reporter_publishes_threats(router, who):
    with router.as_("observer") as obs, router.as_(who) as bad, router.as_("reporter") as rep:
        inbox = Inbox(obs, f"mumt/{M}/threat/*")

        def spoof() -> None:
            put_json(bad, f"mumt/{M}/threat/fake", {**THREAT, "weight": 9})
            bad.delete(f"mumt/{M}/threat/real")

        _denied(
            inbox,
            lambda: put_json(rep, f"mumt/{M}/threat/real", THREAT),
            spoof,
            lambda m: m != THREAT,
            f"a threat from {who}",
        )


@pytest.mark.parametrize("who", ["unit-u1", "commander", "observer"])
def test_only_a_reporter_puts_keep_out_zones(router, who):
    zone = {"polygon": [[[0, 0], [10, 0], [10, 10], [0, 0]]]}
    with router.as_("observer") as obs, router.as_(who) as bad, router.as_("reporter") as rep:
        inbox = Inbox(obs, f"mumt/{M}/zone/*")

        def spoof() -> None:
            put_json(bad, f"mumt/{M}/zone/fake", {"circle": {"centre": [5, 5], "radius_m": 100}})
            bad.delete(f"mumt/{M}/zone/real")

        _denied(
            inbox,
            lambda: put_json(rep, f"mumt/{M}/zone/real", zone),
            spoof,
            lambda m: m != zone,
            f"a zone from {who}",
        )


@pytest.mark.parametrize("who", ["unit-u2", "unit-u1", "reporter", "commander", "fleet"])
def test_only_the_planner_publishes_directions(router, who):
    with router.as_("unit-u1") as u1, router.as_(who) as bad, router.as_("planner") as planner:
        inbox = Inbox(u1, f"mumt/{M}/unit/u1/direction")
        _denied(
            inbox,
            lambda: put_json(planner, f"mumt/{M}/unit/u1/direction", DIRECTION),
            lambda: put_json(bad, f"mumt/{M}/unit/u1/direction", {**DIRECTION, "vector": [-1.0, 0.0]}),
            lambda m: m["vector"] != [1.0, 0.0],
            f"a direction from {who}",
        )


def test_a_unit_reads_only_its_own_direction(router):
    with router.as_("unit-u2") as u2, router.as_("planner") as planner:
        own = Inbox(u2, f"mumt/{M}/unit/u2/direction")
        other = Inbox(u2, f"mumt/{M}/unit/u1/direction")
        wide = Inbox(u2, f"mumt/{M}/unit/*/direction")
        _settle()
        put_json(planner, f"mumt/{M}/unit/u1/direction", DIRECTION)
        put_json(planner, f"mumt/{M}/unit/u2/direction", {**DIRECTION, "unit": "u2"})
        assert own.get()["unit"] == "u2"
        _never(other, "u1's direction to u2")
        assert wide.get()["unit"] == "u2"  # its own, through a wider subscription
        _never(wide, "u1's direction through a wildcard", where=lambda m: m["unit"] == "u1")


def test_no_fake_planner_token_or_status(router):
    """What made ``pfp health`` exit 0 after the real planner died: now refused at the router."""
    with router.as_("observer") as obs, router.as_("unit-u1") as fake, router.as_("commander") as fake2:
        tokens: queue.Queue[str] = queue.Queue()
        sub = obs.liveliness().declare_subscriber(
            f"mumt/{M}/alive/planner/*", lambda s: tokens.put(str(s.key_expr)), history=True
        )
        _settle()
        held = [
            fake.liveliness().declare_token(f"mumt/{M}/alive/planner/planner"),
            fake2.liveliness().declare_token(f"mumt/{M}/alive/planner/evil"),
            fake.declare_queryable(f"mumt/{M}/planner/planner/status", lambda q: q.reply(q.key_expr, b"{}")),
            fake2.declare_queryable(f"mumt/{M}/planner/*/status", lambda q: q.reply(q.key_expr, b"{}")),
        ]
        _settle()
        replies = list(obs.get(f"mumt/{M}/planner/*/status", timeout=1.0))
        assert [r for r in replies if r.ok is not None] == []
        alive = list(obs.liveliness().get(f"mumt/{M}/alive/planner/*", timeout=1.0))
        assert [r for r in alive if r.ok is not None] == []
        with pytest.raises(queue.Empty):
            tokens.get(timeout=NOT_DELIVERED_S)
        # the real planner's token and status do get through
        with router.as_("planner") as planner:
            held += [
                planner.liveliness().declare_token(f"mumt/{M}/alive/planner/planner"),
                planner.declare_queryable(
                    f"mumt/{M}/planner/planner/status", lambda q: q.reply(q.key_expr, b'{"ok": 1}')
                ),
            ]
            assert tokens.get(timeout=5) == f"mumt/{M}/alive/planner/planner"
            assert _answers(obs, f"mumt/{M}/planner/*/status") == [{"ok": 1}]
            for h in held:
                h.undeclare()
        sub.undeclare()


def test_a_unit_cannot_hold_another_units_token(router):
    with router.as_("observer") as obs, router.as_("unit-u2") as u2:
        tokens: queue.Queue[str] = queue.Queue()
        sub = obs.liveliness().declare_subscriber(
            f"mumt/{M}/alive/unit/*", lambda s: tokens.put(str(s.key_expr)), history=True
        )
        _settle()
        bad = u2.liveliness().declare_token(f"mumt/{M}/alive/unit/u1")
        good = u2.liveliness().declare_token(f"mumt/{M}/alive/unit/u2")
        assert tokens.get(timeout=5) == f"mumt/{M}/alive/unit/u2"
        with pytest.raises(queue.Empty):
            tokens.get(timeout=NOT_DELIVERED_S)
        bad.undeclare()
        good.undeclare()
        sub.undeclare()


def test_connecting_without_credentials_is_refused(router):
    plain = zenoh.Config()
    plain.insert_json5("mode", '"client"')
    plain.insert_json5("scouting/multicast/enabled", "false")
    scheme = "tls" if router.tls else "tcp"
    plain.insert_json5("connect/endpoints", json.dumps([f"{scheme}/127.0.0.1:{router.port}"]))
    if router.tls:  # trusts the CA but shows no certificate of its own
        plain.insert_json5("transport/link/tls/root_ca_certificate", json.dumps(str(router.out / "ca.pem")))
    with pytest.raises(zenoh.ZError):
        zenoh.open(plain).close()
    if not router.tls:
        wrong = router.config_of("unit-u1")
        wrong.insert_json5("transport/auth/usrpwd/password", '"not-the-password"')
        with pytest.raises(zenoh.ZError):
            zenoh.open(wrong).close()
        # plain TCP to the router with no usrpwd at all
        tcp = zenoh.Config()
        tcp.insert_json5("mode", '"client"')
        tcp.insert_json5("scouting/multicast/enabled", "false")
        tcp.insert_json5("connect/endpoints", json.dumps([f"tcp/127.0.0.1:{router.port}"]))
        with pytest.raises(zenoh.ZError):
            zenoh.open(tcp).close()


def test_a_certificate_from_another_ca_is_refused(router, tmp_path):
    if not router.tls:
        pytest.skip("mutual TLS only")
    done = subprocess.run(
        [sys.executable, str(GEN_CERTS), "--out", str(tmp_path), "unit-u1"], capture_output=True, timeout=60
    )
    assert done.returncode == 0
    conf = router.config_of("unit-u1")
    conf.insert_json5("transport/link/tls/connect_private_key", json.dumps(str(tmp_path / "unit-u1-key.pem")))
    conf.insert_json5("transport/link/tls/connect_certificate", json.dumps(str(tmp_path / "unit-u1.pem")))
    with pytest.raises(zenoh.ZError):
        zenoh.open(conf).close()


def test_oversized_payloads_are_dropped_by_zenoh(router):
    """transport/link/rx/max_message_size: a 1 MiB put never reaches a subscriber; 100 KB does, before and after."""
    with router.as_("observer") as obs, router.as_("reporter") as rep:
        inbox = Inbox(obs, f"mumt/{M}/threat/*")
        _denied(
            inbox,
            lambda: put_json(rep, f"mumt/{M}/threat/ok", {**THREAT, "pad": "y" * 100_000}),
            lambda: put_json(rep, f"mumt/{M}/threat/big", {"big": "x" * (1 << 20)}),  # valid JSON, 1 MiB
            lambda m: "big" in m,
            "a 1 MiB payload",
        )


# -- allowed: the real flows under the same config ------------------------------------------
def test_a_real_planner_answers_a_unit_through_the_acl(router):
    from pfp_service.node.config import ServeConfig
    from pfp_service.node.node import PlannerNode

    with router.as_("planner") as ps:
        node = PlannerNode(ps, ServeConfig(mission=M, planner_id="planner", mode="client"))
        node.start()
        try:
            with router.as_("unit-u1") as u1, router.as_("observer") as obs:
                token = u1.liveliness().declare_token(f"mumt/{M}/alive/unit/u1")
                inbox = Inbox(u1, f"mumt/{M}/unit/u1/direction")
                events = Inbox(obs, f"mumt/{M}/event/*")
                _settle()
                put_json(u1, f"mumt/{M}/unit/u1/goal", {"position": [10, 0]})
                # a declared publisher, as the handheld and the fleet use: it sends only once the
                # router has told it of a matching subscriber (the planner's unit/*/state)
                pub = u1.declare_publisher(
                    f"mumt/{M}/unit/u1/state", encoding=zenoh.Encoding.APPLICATION_JSON
                )
                deadline = time.monotonic() + 10
                d = None
                seq = 0
                while time.monotonic() < deadline:  # the goal and the state race: report until en_route
                    seq += 1
                    pub.put(json.dumps({"position": [0.0, 0.0], "seq": seq}).encode())
                    d = inbox.get(where=lambda m, s=seq: m.get("seq") == s)
                    if d["status"] == "en_route":
                        break
                assert d is not None and d["status"] == "en_route"
                assert d["vector"][0] == pytest.approx(1.0, abs=1e-6)
                # the unit previews its own path; the planner's status answers an observer
                assert _answers(u1, f"mumt/{M}/preview/u1")[0]["status"] == "reached"
                assert _answers(obs, f"mumt/{M}/planner/*/status")[0]["planner"] == "planner"
                # a reporter's threat makes the planner replan and say so on events
                with router.as_("reporter") as rep:
                    put_json(rep, f"mumt/{M}/threat/e1", {**THREAT, "position": [5, 3]})
                    ev = events.get(timeout=10, where=lambda e: e.get("kind") == "replan")
                    assert "u1" in ev["units"]
                token.undeclare()
                pub.undeclare()
        finally:
            node.stop()


def test_health_and_fleet_commands_connect_with_a_certificate_endpoint(router):
    """Every pfp client takes only ``--connect``; with mTLS that endpoint carries the certificate."""
    if not router.tls:
        pytest.skip(
            "usrpwd identities are tested in test_client_zenoh_config.py; here mutual TLS goes in the endpoint"
        )
    from pfp_service.node.config import ServeConfig
    from pfp_service.node.node import PlannerNode

    endpoints = dict(
        line.split(" ", 1) for line in (router.out / "endpoints.txt").read_text().splitlines() if line
    )
    with router.as_("planner") as ps:
        node = PlannerNode(ps, ServeConfig(mission=M, planner_id="planner", mode="client"))
        node.start()
        try:
            cmd = [sys.executable, "-m", "pfp_service"]
            for who, what in (("observer", "health"), ("planner", "health"), ("observer", "status")):
                done = subprocess.run(
                    [*cmd, what, "--mission", M, "--connect", endpoints[who], "--timeout", "3"],
                    capture_output=True,
                    text=True,
                    timeout=60,
                    cwd=ROOT,
                )
                assert done.returncode == 0, f"pfp {what} as {who}: {done.stdout}{done.stderr}"
            team = router.out.parent / "team.yaml"
            fleet = subprocess.run(
                [*cmd, "fleet", "--team", str(team), "--mission", M, "--connect", endpoints["fleet"]]
                + ["--speed-up", "20", "--until-arrived", "--duration-s", "60"],
                capture_output=True,
                text=True,
                timeout=120,
                cwd=ROOT,
            )
            assert fleet.returncode == 0, fleet.stdout[-2000:] + fleet.stderr[-2000:]
        finally:
            node.stop()
