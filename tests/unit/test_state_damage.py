"""Durable state that survives its own damage: a corrupt page, a corrupt row, a full disk, a read-only file.

The planner either starts and names what it set aside (one warning line, and
the ``restored`` event's ``corrupt`` and ``set_aside``), or exits 2 with one
line naming the state file.  Never a traceback.
"""

from __future__ import annotations

import contextlib
import json
import shutil
import sqlite3
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest
import zenoh

from pfp_service.node.statefile import state_files
from pfp_service.node.store import Store
from pfp_service.wire import Goal, ThreatUpdate
from pfp_service.world.world import GoalSet, InputRejected, MissionRestored, ThreatPut
from tests.zenoh_util import ROOT, Inbox, client, free_port, wait_for_planner

T = dict(facing_deg=225.0, sigma_range=1.0, sigma_lateral=0.7, skew=2.0)
GARBAGE = bytes(range(256)) * 32  # 8 KiB


def _fill(directory: Path, threats: int = 50, goals: int = 200) -> None:
    store = Store(directory)
    batch = [ThreatPut(f"e{i}", ThreatUpdate(position=(i % 10, 6), **T)) for i in range(threats)]
    batch += [GoalSet(f"u{i}", Goal(position=(10, i % 10))) for i in range(goals)]
    store.commit_inputs(batch, 1000.0, None)
    store.close()


def _scribble(db: Path, offset: int = 4096, data: bytes = GARBAGE) -> None:
    with open(db, "r+b") as f:
        f.seek(offset)
        f.write(data)


@pytest.mark.unit
def test_a_corrupt_page_is_moved_aside_kept_and_the_readable_rows_salvaged(tmp_path):
    _fill(tmp_path)
    db = tmp_path / "state.sqlite3"
    _scribble(db)  # pages 2 and 3: the threats table's root and its index
    store = Store(tmp_path, wall_now=1_700_000_000.0)
    r = store.restore(1000.0)
    store.close()
    aside = Path(r.set_aside)
    assert aside.name == "state.sqlite3.corrupt-20231114T221320Z" and aside.exists()
    assert GARBAGE in aside.read_bytes()  # kept as found
    assert r.corrupt >= 1
    assert (r.kept["threat"], r.kept["goal"]) == (
        0,
        200,
    )  # the goals' pages were readable: every goal is back
    # the fresh file is sound, and a second start finds nothing wrong
    again = Store(tmp_path).restore(1000.0)
    assert (again.corrupt, again.set_aside, again.kept["goal"]) == (0, "", 200)


@pytest.mark.unit
def test_a_file_that_is_not_a_database_starts_empty_and_is_kept(tmp_path):
    (tmp_path / "state.sqlite3").write_bytes(b"this is not SQLite" * 1000)
    store = Store(tmp_path)
    r = store.restore(0.0)
    assert r.inputs == [] and r.corrupt >= 1 and Path(r.set_aside).read_bytes().startswith(b"this is not")
    store.commit_inputs([GoalSet("u", Goal(position=(1, 1)))], 0.0, None)  # and it works
    store.close()
    assert Store(tmp_path).restore(0.0).kept["goal"] == 1


@pytest.mark.unit
def test_rows_past_a_damaged_page_are_salvaged(tmp_path):
    _fill(tmp_path, threats=0, goals=2000)  # goals over many pages
    db = tmp_path / "state.sqlite3"
    con = sqlite3.connect(db)
    leaves = [
        n for (n,) in con.execute("SELECT pageno FROM dbstat WHERE name = 'goals' AND pagetype = 'leaf'")
    ]
    page_size = con.execute("PRAGMA page_size").fetchone()[0]
    con.close()
    middle = leaves[len(leaves) // 2]
    _scribble(db, offset=(middle - 1) * page_size, data=GARBAGE[:page_size])  # one leaf in the middle
    r = Store(tmp_path).restore(0.0)
    assert r.set_aside and r.corrupt >= 1
    assert 1800 < r.kept["goal"] < 2000  # the rest of the table, either side of the lost leaf


@pytest.mark.unit
@pytest.mark.parametrize("kind", ["garbage", "zeros", "one byte"])
def test_damage_to_any_page_never_raises_and_the_store_works_after(tmp_path, kind):
    import random

    seed = 22
    rng = random.Random(seed)
    base = tmp_path / "base"
    _fill(base)
    pages = (base / "state.sqlite3").stat().st_size // 4096
    for page in range(pages):
        d = tmp_path / f"p{page}"
        shutil.copytree(base, d)
        if kind == "garbage":
            _scribble(d / "state.sqlite3", page * 4096, rng.randbytes(4096))
        elif kind == "zeros":
            _scribble(d / "state.sqlite3", page * 4096, bytes(4096))
        else:
            _scribble(d / "state.sqlite3", page * 4096 + rng.randrange(4096), rng.randbytes(1))
        store = Store(d)
        r = store.restore(1000.0)  # never raises
        assert r.kept["goal"] <= 200 and r.kept["threat"] <= 50, (seed, page)
        assert bool(r.set_aside) <= (r.corrupt >= 1), (seed, page)
        store.commit_inputs([GoalSet("after", Goal(position=(1, 1)))], 1000.0, None)
        store.close()
        assert any(i == GoalSet("after", Goal(position=(1, 1))) for i in Store(d).restore(1000.0).inputs)


@pytest.mark.unit
def test_the_wal_of_a_killed_planner_shadows_a_damaged_page(tmp_path):
    live = tmp_path / "live"
    store = Store(live)
    store.commit_inputs([GoalSet(f"u{i}", Goal(position=(1, 1))) for i in range(50)], 0.0, None)
    # as kill -9 leaves it: the database and its WAL, never checkpointed
    snap = tmp_path / "snap"
    snap.mkdir()
    for name in ("state.sqlite3", "state.sqlite3-wal"):
        shutil.copy(live / name, snap / name)
    store.close()
    _scribble(snap / "state.sqlite3")
    r = Store(snap).restore(0.0)
    assert (r.kept["goal"], r.corrupt, r.set_aside) == (50, 0, "")


@pytest.mark.unit
def test_a_corrupt_row_is_skipped_named_kept_and_the_rest_loads(tmp_path):
    _fill(tmp_path, threats=3, goals=5)
    con = sqlite3.connect(tmp_path / "state.sqlite3")
    con.execute("UPDATE goals SET body = x'ffff00' WHERE unit = 'u2'")
    con.execute("UPDATE threats SET body = '{\"position\": \"nowhere\"}' WHERE id = 'e1'")
    con.execute("INSERT INTO missions VALUES ('u3', 1, 0.0, 0.0, 'not json')")
    con.commit()
    con.close()
    r = Store(tmp_path).restore(1000.0)
    assert set(r.skipped) == {"goals/u2", "threats/e1", "missions/u3"} and r.corrupt == 3
    assert (r.kept["threat"], r.kept["goal"], r.missions, r.set_aside) == (2, 4, 0, "")
    assert not any(isinstance(i, MissionRestored) for i in r.inputs)  # u3 comes back from its goal
    assert GoalSet("u3", Goal(position=(10, 3))) in r.inputs
    # kept out of the way, so the next start is clean
    assert state_files(tmp_path).counts["set_aside"] == 3
    assert Store(tmp_path).restore(1000.0).corrupt == 0


@pytest.mark.unit
def test_a_full_disk_is_named_as_such(tmp_path):
    store = Store(tmp_path)
    store._db.execute("PRAGMA max_page_count = 1")  # SQLite's own SQLITE_FULL, as a full disk gives it
    batch = [GoalSet(f"u{i}", Goal(position=(1, 1))) for i in range(500)]  # more than the pages there are
    rejected = store.commit_batch(batch, 0.0, None, "m")
    assert all(isinstance(r, InputRejected) for r in rejected)
    rej = rejected[0]
    assert isinstance(rej, InputRejected)
    assert "disk is full" in rej.error.reason and str(tmp_path / "state.sqlite3") in rej.error.reason
    assert "no transaction is active" not in rej.error.reason


@pytest.mark.unit
def test_a_read_only_database_is_named_as_such(tmp_path):
    store = Store(tmp_path)
    store._db.execute("PRAGMA query_only = 1")  # SQLITE_READONLY, as a read-only file or mount gives it
    (rej,) = store.commit_batch([ThreatPut("e", ThreatUpdate(position=(1, 1), **T))], 0.0, None, "m")
    assert isinstance(rej, InputRejected) and "read-only" in rej.error.reason


# -- through a real `pfp serve` ----------------------------------------------------------------
def _router(endpoint):
    conf = zenoh.Config()
    conf.insert_json5("mode", '"router"')
    conf.insert_json5("listen/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(conf)


def _serve(endpoint: str, mission: str, state: Path, log: Path) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "pfp_service", "serve", "--mode", "client", "--connect", endpoint,
         "--mission", mission, "--state-dir", str(state)],
        cwd=ROOT, stdout=log.open("w"), stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip


def _restored_from_serve(tmp_path: Path, state: Path) -> tuple[dict, str]:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    mission = "s" + uuid.uuid4().hex[:8]
    log = tmp_path / "serve.log"
    with _router(endpoint), client(endpoint) as s:
        events = Inbox(s, f"mumt/{mission}/event/restored")
        proc = _serve(endpoint, mission, state, log)
        try:
            wait_for_planner(endpoint, mission)
            ev = events.get(timeout=30)
        finally:
            proc.terminate()
            with contextlib.suppress(subprocess.TimeoutExpired):
                proc.wait(timeout=10)
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        assert proc.returncode == 0, log.read_text()
    return ev, log.read_text()


@pytest.mark.proc
def test_serve_with_a_corrupt_page_starts_and_names_what_it_set_aside(tmp_path):
    state = tmp_path / "state"
    _fill(state)
    _scribble(state / "state.sqlite3")
    ev, text = _restored_from_serve(tmp_path, state)
    assert "Traceback" not in text, text
    assert ev["corrupt"] >= 1 and ev["goals"] == 200
    assert Path(ev["set_aside"]).parent == state and Path(ev["set_aside"]).exists()
    (line,) = [x for x in text.splitlines() if "set aside" in x]
    assert "WARNING" in line and ev["set_aside"] in line and str(state / "state.sqlite3") in line


@pytest.mark.proc
def test_serve_with_a_corrupt_row_starts_and_names_the_row(tmp_path):
    state = tmp_path / "state"
    _fill(state, threats=2, goals=3)
    con = sqlite3.connect(state / "state.sqlite3")
    con.execute("UPDATE goals SET body = x'ffff00' WHERE unit = 'u1'")
    con.commit()
    con.close()
    ev, text = _restored_from_serve(tmp_path, state)
    assert "Traceback" not in text and "malformed JSON" not in text.split("set aside")[0], text
    assert (ev["corrupt"], ev["goals"], ev["threats"], ev["set_aside"]) == (1, 2, 2, "")
    (line,) = [x for x in text.splitlines() if "set aside" in x]
    assert "goals/u1" in line


@pytest.mark.proc
def test_serve_on_an_unusable_state_file_is_one_line_naming_it_and_exit_2(tmp_path):
    state = tmp_path / "state"
    state.mkdir()
    (state / "state.sqlite3").mkdir()  # a directory where the database should be: it cannot be opened
    t0 = time.monotonic()
    r = subprocess.run(
        [sys.executable, "-m", "pfp_service", "serve", "--listen", f"tcp/127.0.0.1:{free_port()}",
         "--state-dir", str(state)],
        capture_output=True, text=True, timeout=60, cwd=ROOT,
    )  # fmt: skip
    assert r.returncode == 2, r.stderr
    (line,) = r.stderr.strip().splitlines()
    assert str(state / "state.sqlite3") in line and "Traceback" not in r.stderr
    assert time.monotonic() - t0 < 60
