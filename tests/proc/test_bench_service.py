"""``pfp bench service`` in small, as a user runs it: the bench keeps working and its JSON keeps its fields.

No timing is asserted: these machines are shared and noisy.  What is checked
is that every phase ran against a real planner and a real echo responder and
reported every figure BENCHMARKS.md quotes.
"""

from __future__ import annotations

import json

import pytest

from tests.conftest import run_pfp

pytestmark = pytest.mark.proc

LATENCY = {"sent", "answered", "unanswered_fraction", "p50_ms", "p90_ms", "p99_ms", "max_ms"}
STEADY = LATENCY | {"input_per_s", "output_per_s", "cpu_percent", "rss_mb", "peak_rss_mb", "statuses"}
STORM = {"goals", "guided", "all_guided_s", "deliberations_started", "all_deliberated_s", "bystander"}
FANOUT = {
    "affected",
    "redirected",
    "all_redirected_ms",
    "all_deliberated_s",
    "pushes_sent",
    "pushes_delivered",
}


def test_bench_service_json_has_every_figure():
    r = run_pfp(
        "bench", "service", "--units", "10", "--rate", "10", "--threats", "5", "--duration", "1",
        "--echo", "--find-max", "--probe-s", "0.5", "--json",
        timeout=240,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    assert {"machine", "load", "planner", "echo", "targets"} <= doc.keys()
    for kind in ("planner", "echo"):
        steady = doc[kind]["steady"]
        assert steady.keys() >= STEADY, kind
        assert steady["sent"] > 0 and steady["answered"] > 0, (kind, steady)
        assert doc[kind]["exit"]["exit_code"] == 0, doc[kind]["exit"]
    p = doc["planner"]
    assert p["storm"].keys() >= STORM
    assert p["storm"]["guided"] == 10  # every freshly goaled unit got a direction
    assert p["fanout"].keys() >= FANOUT
    assert p["fanout"]["affected"] is not None  # the planner's replan event arrived
    assert p["exit"]["error_lines"] == 0, p["exit"]["first_errors"]
    for kind in ("planner", "echo"):
        fm = doc[kind]["find_max"]
        assert fm["probes"] and {"rate_hz", "p99_ms", "unanswered_fraction", "ok"} <= fm["probes"][0].keys()
        assert "max_per_s" in fm
    assert doc["planner"]["find_max"]["deliberations"].keys() >= {"landed", "left", "waited_s"}
    for kind in ("planner", "echo"):  # CPU per state compared at 5,000/s, the deliberations landed first
        assert doc[kind]["cpu_rate"].keys() >= STEADY, kind
    assert doc["planner"]["cpu_rate"]["deliberations"].keys() >= {"landed", "left", "waited_s"}
    assert doc["planner"]["steady_after"]["deliberations"]["landed"] in (True, False)
    assert any(t["target"].startswith("CPU per state at 5000/s") for t in doc["targets"])
    assert doc["planner"]["steady"]["processes"] >= 2  # the planner and its worker processes, all counted
    assert doc["echo"]["steady"]["processes"] == 1
    assert all({"target", "measured", "limit", "met"} <= t.keys() for t in doc["targets"])


def test_bench_service_planners_compares_one_with_k_and_counts_doubles():
    r = run_pfp(
        "bench", "service", "--units", "12", "--rate", "5", "--threats", "3", "--duration", "1",
        "--no-storm", "--no-fanout", "--planners", "2", "--json",
        timeout=240,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    so = json.loads(r.stdout)["scale_out"]
    assert so["planners"] == 2 and [run["planners"] for run in so["runs"]] == [1, 2]
    for run in so["runs"]:
        st = run["steady"]
        assert st.keys() >= STEADY | {"answered_per_s", "answered_twice", "units_answered_by_two"}, run
        assert st["answered"] > 0 and st["answered_twice"] == 0 and st["units_answered_by_two"] == 0, st
        assert run["ownership_settled_s"] is not None  # the planners owned every unit between them
        assert len(st["cpu_percent_by_process"]) == run["planners"] + 1  # the router and each planner
        assert run["exit"]["exit_code"] == 0 and run["exit"]["error_lines"] == 0, run["exit"]
    assert sum(so["runs"][1]["steady"]["units_per_planner"].values()) == 12
    got = so["runs"][1]["steady"]["states_by_planner"]  # each planner's own count, from its status
    assert set(got) == {"planner", "planner-1"} and all(n > 0 for n in got.values()), got
    assert set(so["vs_one"]) >= {"answered_per_s", "p50_ms", "p99_ms"}


def test_bench_service_state_keys_gives_a_row_per_key_in_one_run():
    """Issue 34: the plain key (a client that does not shard) against the shard key, each answered."""
    for keys_mode, rows in (("both", {"shard", "plain"}), ("mixed", {"mixed"})):
        r = run_pfp(
            "bench", "service", "--units", "10", "--rate", "5", "--threats", "3", "--duration", "1",
            "--no-storm", "--no-fanout", "--state-keys", keys_mode, "--json",
            timeout=240,
        )  # fmt: skip
        assert r.returncode == 0, r.stderr
        doc = json.loads(r.stdout)
        by_key = doc["planner"]["steady_by_key"]
        assert set(by_key) == rows
        halves = by_key["mixed"]["by_key"] if keys_mode == "mixed" else by_key
        assert set(halves) == {"shard", "plain"}
        for key, st in halves.items():
            assert st["sent"] > 0 and st["answered"] >= 0.8 * st["sent"], (
                keys_mode,
                key,
                st,
            )  # answered on both
        names = {t["target"] for t in doc["targets"]}
        assert {"plain key p50 <= 1.2x shard key p50", "plain key unanswered <= shard key's + 20 %"} <= names


def test_bench_service_teams_compares_teams_and_dispersion_with_a_plain_planner():
    r = run_pfp(
        "bench", "service", "--units", "16", "--rate", "4", "--threats", "3", "--duration", "2",
        "--no-storm", "--teams", "--teams-rounds", "2", "--json",
        timeout=300,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    t = json.loads(r.stdout)["teams"]
    assert t["teams"]["teams"] == 4  # a team for every four units
    assert t["scene"] == "march"  # spaced at the separation by default (--dense: the crowd)
    assert len(t["rounds"]) == 2
    for row in t["rounds"]:
        for kind in ("plain", "teams"):  # CPU is read in clock ticks: a second of a light load may read 0
            assert row[kind]["us_per_state"] is not None and row[kind]["us_per_state"] >= 0, row
            # both planners answered (a bench's shape, not its speed: a loaded machine may leave many late)
            assert row[kind]["unanswered_fraction"] < 0.95, row
        assert "ratio" in row
    for kind in ("plain", "teams"):  # a tick that fails to publish logs an error: none did
        assert t[kind]["exit"]["exit_code"] == 0 and t[kind]["exit"]["error_lines"] == 0, t[kind]["exit"]
    for kind in ("plain", "teams"):  # the wave on the same march, the teams planner's beside the plain one's
        assert t["fanout"][kind].keys() >= FANOUT, kind
        assert t["fanout"][kind]["affected"] is not None, kind  # the planner's replan event arrived
    rows = {
        row["target"]: row for row in json.loads(r.stdout)["targets"] if row["target"].startswith("teams")
    }
    ratio = next(row for name, row in rows.items() if "CPU per state" in name)
    wave = next(row for name, row in rows.items() if "fan-out" in name)
    assert ratio["measured"] == t["ratio_median"]
    assert wave["measured"] == t["fanout"]["teams"]["all_redirected_ms"] and wave["limit"] == 50.0
