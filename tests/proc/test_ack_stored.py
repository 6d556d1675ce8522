"""An acknowledgement means stored (issue 35): a real planner on a real full disk (a tiny tmpfs) acks no
write it did not store, and names the cause; the write order is kept with the writes, so an older put
asked again after a restart never undoes an acknowledged delete."""

from __future__ import annotations

import ctypes
import ctypes.util
import errno
import json
import os
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import msgspec
import pytest
import zenoh

from pfp_service.node.store import Store
from pfp_service.wire import keys
from pfp_service.wire.delivery import Deliverer, WriteMark, decode_ack
from tests.zenoh_util import client, planner_process

pytestmark = pytest.mark.proc

_LIBC = ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True)


@contextmanager
def _tiny_disk(where: Path, size: str) -> Iterator[Path]:
    """A tmpfs of ``size`` mounted at ``where`` (needs root's CAP_SYS_ADMIN; skips without it)."""
    where.mkdir()
    if _LIBC.mount(b"tmpfs", str(where).encode(), b"tmpfs", 0, f"size={size},mode=0700".encode()) != 0:
        pytest.skip(f"cannot mount a tmpfs here: {os.strerror(ctypes.get_errno())}")
    try:
        yield where
    finally:
        _LIBC.umount2(str(where).encode(), 2)  # MNT_DETACH: gone even if something still holds it


def _fill(disk: Path) -> int:
    """Fill ``disk`` to the last byte; returns the bytes written."""
    written = 0
    fd = os.open(disk / "filler", os.O_WRONLY | os.O_CREAT, 0o600)
    try:
        for block in (65536, 4096, 512, 1):
            while True:
                try:
                    written += os.write(fd, b"\0" * block)
                except OSError as exc:
                    assert exc.errno == errno.ENOSPC
                    break
    finally:
        os.close(fd)
    return written


@contextmanager
def _planner(mission: str, state_dir: Path) -> Iterator[zenoh.Session]:
    """``pfp serve --state-dir STATE_DIR`` as a subprocess, and a client session to it."""
    with (
        planner_process("--state-dir", str(state_dir), mission=mission) as (endpoint, _proc),
        client(endpoint) as s,
    ):
        yield s


def _ask(session: zenoh.Session, key: str, payload: bytes | None, mark: WriteMark, live: bool = True) -> str:
    """One acknowledged write as ``Deliverer`` sends it (its put, then its query; ``live`` False: asked
    again, the query only); the ack's outcome and reason."""
    att = msgspec.json.encode(mark)
    if live and payload is None:
        session.delete(key, attachment=att)
    elif live:
        session.put(key, payload, attachment=att)
    for reply in session.get(
        key, payload=payload, attachment=att, target=zenoh.QueryTarget.ALL, timeout=10.0
    ):
        if reply.ok is not None:
            ack = decode_ack(reply.ok.payload.to_bytes())
            return ack.outcome + (f": {ack.reason}" if ack.reason else "")
    return "no answer"


def test_on_a_full_disk_no_write_is_acknowledged_that_was_not_stored(tmp_path):
    mission = "full" + uuid.uuid4().hex[:8]
    outcomes: dict[str, str] = {}
    said: list[str] = []
    with _tiny_disk(tmp_path / "disk", "512k") as disk:
        state = disk / "state"
        with _planner(mission, state) as writer:
            filled = _fill(disk)
            writer_id = str(writer.info.zid())
            for i in range(300):  # raw writes, as the attack sent them
                key = keys.unit_goal(mission, f"u{i}")
                body = json.dumps({"position": [float(i), 1.0]}).encode()
                outcomes[key] = _ask(writer, key, body, WriteMark(t=time.time(), writer=writer_id))
            with Deliverer(writer, mission, said.append) as d:  # and through the project's own writer
                for i in range(3):
                    d.put(
                        keys.unit_goal(mission, f"d{i}"), json.dumps({"position": [1.0, float(i)]}).encode()
                    )
                assert d.wait_delivered(30.0), said
        os.remove(disk / "filler")
        stored = {
            keys.unit_goal(mission, inp.unit)
            for inp in Store(state).restore(time.time()).inputs
            if type(inp).__name__ == "GoalSet"
        }
    acked = {k for k, o in outcomes.items() if o.split(":")[0] in ("applied", "duplicate")}
    refused = {k: o for k, o in outcomes.items() if o.startswith("rejected")}
    print(
        f"disk filled with {filled:,} bytes; 300 raw writes: {len(acked)} acked, {len(refused)} refused, "
        f"{len(acked - stored)} acked but not stored; the Deliverer said: {said}"
    )
    assert refused, f"the disk never refused a write: {outcomes}"
    assert acked - stored == set(), "acknowledged and never stored"
    assert all("not stored: the disk is full" in o for o in refused.values()), set(refused.values())
    assert not set(refused) & stored
    delivered = {keys.unit_goal(mission, f"d{i}") for i in range(3)}
    told = [line for line in said if "rejected" in line]
    assert all("the disk is full" in line for line in told), said
    assert len(told) + len(delivered & stored) == 3, (said, delivered & stored)


def test_an_older_put_asked_again_after_a_restart_does_not_undo_an_acknowledged_delete(tmp_path):
    mission = "order" + uuid.uuid4().hex[:8]
    key = keys.unit_goal(mission, "u1")
    body = b'{"position": [5.0, 5.0]}'
    put_a = WriteMark(t=time.time() - 60, writer="writer-a")  # A put it a minute ago, while no planner ran
    with _planner(mission, tmp_path / "state") as b:
        assert _ask(b, key, body, put_a) in ("applied", "duplicate")  # A's put reached it first ...
        delete_b = WriteMark(t=time.time(), writer="writer-b", delete=True)
        assert _ask(b, key, None, delete_b) in ("applied", "duplicate")  # ... then B's delete, acked
    with _planner(mission, tmp_path / "state") as a:
        # A never heard its ack and asks again after the restart: it must not bring the goal back
        got = _ask(a, key, body, put_a, live=False)
    assert got == "superseded", got
    restored = Store(tmp_path / "state").restore(time.time())
    assert not [i for i in restored.inputs if getattr(i, "unit", None) == "u1"], restored.inputs
