"""Hostile recordings: ``pfp report`` and ``pfp replay`` refuse a decompression bomb, a chunk declaring
2^62 bytes or 4e12 decoded, and a message flood, in one line naming the file and the limit, before
decompressing it (bounds.LIMITS, mcap_*)."""

from __future__ import annotations

import struct
import time
import zlib

import pytest
import zstandard
from pfp_clients.record.mcapcheck import MAGIC
from pfp_clients.record.mcapfile import read_record

from pfp_service.errors import InputError
from tests.conftest import run_pfp


def _s(b: bytes) -> bytes:
    return struct.pack("<I", len(b)) + b


def _rec(op: int, content: bytes) -> bytes:
    return struct.pack("<BQ", op, len(content)) + content


def _message(channel: int, t_ns: int, data: bytes) -> bytes:
    return _rec(0x05, struct.pack("<HIQQ", channel, 0, t_ns, t_ns) + data)


def _chunk(
    records: bytes, compression: str = "zstd", declared: int | None = None, stored: int | None = None
) -> bytes:
    data = zstandard.ZstdCompressor().compress(records) if compression == "zstd" else records
    size = len(records) if declared is None else declared
    body = struct.pack("<QQQI", 0, 0, size, zlib.crc32(records)) + _s(compression.encode())
    body += struct.pack("<Q", len(data) if stored is None else stored) + data
    return _rec(0x06, body)


def _record(*chunks: bytes, mission: str = "m1") -> bytes:
    meta = _s(b"mission") + _s(mission.encode())
    out = MAGIC + _rec(0x01, _s(b"") + _s(b"test"))
    out += _rec(0x0C, _s(b"pfp") + struct.pack("<I", len(meta)) + meta)
    out += b"".join(chunks)
    out += _rec(0x0F, struct.pack("<I", 0)) + _rec(0x02, struct.pack("<QQI", 0, 0, 0)) + MAGIC
    return out


def _channel(cid: int, topic: str) -> bytes:
    return _rec(0x04, struct.pack("<HH", cid, 0) + _s(topic.encode()) + _s(b"json") + struct.pack("<I", 0))


def _bomb(messages: int, per_chunk: int) -> bytes:
    """``messages`` states in zstd chunks of ``per_chunk``, streamed so the test never holds them decoded."""
    one = _message(1, 1_000_000_000, b'{"position":[0,0]}')
    chunks = [_chunk(_channel(1, "/mumt/m1/unit/u1/state"))]
    for _ in range(messages // per_chunk):
        records_len = len(one) * per_chunk
        cobj = zstandard.ZstdCompressor(level=19).compressobj(size=records_len)
        data = b"".join([*(cobj.compress(one * 10_000) for _ in range(per_chunk // 10_000)), cobj.flush()])
        body = struct.pack("<QQQI", 0, 0, records_len, 0) + _s(b"zstd") + struct.pack("<Q", len(data)) + data
        chunks.append(_rec(0x06, body))
    return _record(*chunks)


HOSTILE = {
    "bomb-2M.mcap": (lambda: _bomb(2_000_000, 2_000_000), "(mcap_chunk_bytes)"),
    "bomb-chunks.mcap": (lambda: _bomb(2_000_000, 250_000), "(mcap_ratio)"),
    "data-2e62.mcap": (lambda: _record(_chunk(_channel(1, "/x"), stored=2**62)), "declares"),
    "record-2e62.mcap": (
        lambda: MAGIC + struct.pack("<BQ", 0x06, 2**62) + b"\0" * 64,
        "declares 4,611,686,018,427,387,904",
    ),
    "declared-4e12.mcap": (
        lambda: _record(_chunk(_channel(1, "/x"), declared=4 * 10**12)),
        "(mcap_chunk_bytes)",
    ),
}


@pytest.mark.unit
@pytest.mark.parametrize("name", sorted(HOSTILE))
def test_a_hostile_record_is_refused_before_it_is_decompressed(tmp_path, name):
    make, limit = HOSTILE[name]
    p = tmp_path / name
    p.write_bytes(make())
    t0 = time.perf_counter()
    with pytest.raises(InputError) as got:
        read_record(p)
    assert time.perf_counter() - t0 < 1.0
    assert name in str(got.value) and limit in str(got.value), got.value


@pytest.mark.unit
def test_a_zstd_frame_declaring_more_than_its_chunk_is_refused(tmp_path):
    records = _channel(1, "/x") + _message(1, 1, b"{}") * 100
    p = tmp_path / "liar.mcap"
    p.write_bytes(_record(_chunk(records, declared=64)))
    with pytest.raises(InputError, match="frame declares"):
        read_record(p)


@pytest.mark.unit
def test_the_message_budget_is_counted(tmp_path, monkeypatch):
    from pfp_service import bounds

    monkeypatch.setitem(bounds.LIMITS, "mcap_messages", bounds.Limit(50, "", "", ""))
    records = _channel(1, "/mumt/m1/unit/u1/state") + _message(1, 5, b"{}") * 51
    p = tmp_path / "many.mcap"
    p.write_bytes(_record(_chunk(records, compression="")))
    with pytest.raises(InputError, match=r"more than 50 messages \(mcap_messages\)"):
        read_record(p)
    p.write_bytes(_record(_chunk(_channel(1, "/mumt/m1/unit/u1/state") + _message(1, 5, b"{}") * 50)))
    assert len(read_record(p).entries) == 50


@pytest.mark.proc
@pytest.mark.parametrize("command", ["report", "replay"])
def test_report_and_replay_refuse_a_bomb_in_one_line(tmp_path, command):
    p = tmp_path / "bomb.mcap"
    p.write_bytes(_bomb(2_000_000, 250_000))
    assert p.stat().st_size < 64 * 1024
    t0 = time.monotonic()
    args = [command, str(p)] + (["--connect", "tcp/127.0.0.1:9"] if command == "replay" else [])
    r = run_pfp(*args, timeout=60)
    took = time.monotonic() - t0
    assert r.returncode == 2, r.stderr[-2000:]
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "bomb.mcap" in lines[0] and "(mcap_ratio)" in lines[0], r.stderr[-2000:]
    assert took < 10, took
    print(f"pfp {command} bomb.mcap ({p.stat().st_size:,} bytes): exit 2 in {took:.2f} s")
