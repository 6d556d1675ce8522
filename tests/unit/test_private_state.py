"""Private by default (issue 35): the state directory is 0700 and its files 0600 under any umask; and a
position beyond the mission's documented extent (50 km from its origin) is refused on the wire."""

from __future__ import annotations

import os
import stat
import time

import pytest

from pfp_service.errors import InputError
from pfp_service.geo import Origin
from pfp_service.node.store import Store
from pfp_service.wire import Goal, decode_goal, decode_threat, decode_unit_state
from pfp_service.world.events import GoalSet

pytestmark = pytest.mark.unit
ORIGIN = Origin(lat=58.4105, lon=15.6213)


def _mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


@pytest.fixture
def open_umask():
    old = os.umask(0o022)  # the common default, under which these were 0755 and 0644
    try:
        yield
    finally:
        os.umask(old)


def test_the_state_directory_is_0700_and_its_files_0600(tmp_path, open_umask):
    state = tmp_path / "home" / "pfp" / "m1"
    store = Store(state)
    store.commit_inputs([GoalSet("u1", Goal(position=(1.0, 2.0)))], time.time(), None)
    files = sorted(p.name for p in state.iterdir())
    assert {"state.sqlite3", "state.sqlite3-wal", "state.lock"} <= set(files), files
    assert _mode(state) == 0o700 and _mode(state.parent) == 0o700 and _mode(state.parent.parent) == 0o700
    for name in files:
        assert _mode(state / name) == 0o600, (name, oct(_mode(state / name)))
    store.close()


def test_a_state_left_open_by_an_older_planner_is_made_private(tmp_path, open_umask):
    state = tmp_path / "m1"
    Store(state).close()
    os.chmod(state, 0o755)
    os.chmod(state / "state.sqlite3", 0o644)
    Store(state).close()
    assert _mode(state) == 0o700 and _mode(state / "state.sqlite3") == 0o600


def test_the_tak_tombstone_file_is_0600(tmp_path, open_umask):
    from pfp_clients.tak import tombfile
    from pfp_clients.tak.tombs import Tombstone

    path = tmp_path / "state" / tombfile.FILE_NAME
    assert tombfile.save(path, {"a": Tombstone(1.0, 2.0, "tak")}) is None
    assert _mode(path) == 0o600 and _mode(path.parent) == 0o700


@pytest.mark.parametrize(
    ("decode", "body", "path"),
    [
        (decode_goal, b'{"position": [7000000, 0]}', "$.position"),
        (decode_threat, b'{"position": [0, -60000], "sigma_range": 5, "sigma_lateral": 5}', "$.position"),
        (decode_unit_state, b'{"position": [40000, 40000]}', "$.position"),
    ],
)
def test_a_position_beyond_the_missions_extent_is_refused(decode, body, path):
    with pytest.raises(InputError) as got:
        decode(body, None, ORIGIN)
    assert got.value.path == path and "km from the mission origin" in got.value.reason
    decode(body, None, None)  # without an origin metres are abstract: only the wire's own bound holds
    assert decode_goal(b'{"position": [35000, -35000]}', None, ORIGIN).position == (35000.0, -35000.0)
