"""The layout of a mission record in MCAP, its writer and its reader.

One channel per Zenoh key, its topic the key with a leading ``/``
(``/mumt/m1/unit/u1/state``: Foxglove's message paths want the slash), its
message encoding ``json`` and its schema the wire contract's JSON Schema for
that kind of key (``pfp_service.wire.schema``, the same text as ``schemas/``).
A key the contract does not know is kept too, schemaless.  Besides:

* ``/pfp/deleted``: a DELETE on any key (a goal cancelled, a threat removed), ``{"key": ...}``;
* ``/pfp/alive``: liveliness tokens appearing and going, ``{"key": ..., "alive": bool}``;
* ``/pfp/fix/{unit}``: with a known origin, each unit state as a ``foxglove.LocationFix``
  (the Map panel draws it);
* metadata ``pfp``: the mission, the origin (if any), the recorder's version and start time;
* metadata ``pfp.coverage``: what the record missed of the planners' outputs (``coverage.py``),
  each value JSON text.

Log times are the recorder's wall clock at receipt, in nanoseconds.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from pfp_service.bounds import limit
from pfp_service.errors import InputError
from pfp_service.geo import Origin
from pfp_service.wire import keys

__all__ = [
    "ALIVE_TOPIC",
    "DELETED_TOPIC",
    "FIX_PREFIX",
    "Entry",
    "MissionWriter",
    "Record",
    "read_record",
]

DELETED_TOPIC = "/pfp/deleted"
ALIVE_TOPIC = "/pfp/alive"
FIX_PREFIX = "/pfp/fix/"
METADATA = "pfp"
_CLOCK_SLACK_NS = 3600 * 10**9  # recorders' clocks may run an hour ahead of this machine's
COVERAGE = "pfp.coverage"
PROFILE = ""  # no ROS profile: plain JSON with JSON Schema, which Foxglove reads as it is

_KEY_SCHEMA = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "a DELETE on a key",
    "type": "object",
    "properties": {"key": {"type": "string"}},
    "required": ["key"],
}
_ALIVE_SCHEMA = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "a liveliness token appeared or went",
    "type": "object",
    "properties": {"key": {"type": "string"}, "alive": {"type": "boolean"}},
    "required": ["key", "alive"],
}
# Foxglove's own schema name: the Map panel shows any topic of this schema
_FIX_SCHEMA = {
    "title": "foxglove.LocationFix",
    "type": "object",
    "properties": {
        "timestamp": {
            "type": "object",
            "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}},
        },
        "frame_id": {"type": "string"},
        "latitude": {"type": "number"},
        "longitude": {"type": "number"},
        "altitude": {"type": "number"},
        "position_covariance": {"type": "array", "items": {"type": "number"}},
        "position_covariance_type": {"type": "integer"},
    },
}


def _contract_schemas() -> dict[keys.KeyKind, tuple[str, bytes]]:
    """Each published key kind's message name and JSON Schema text, from the contract itself."""
    from pfp_service.wire import schema
    from pfp_service.world import translate

    files = schema.render(translate.supplied())
    out: dict[keys.KeyKind, tuple[str, bytes]] = {}
    for spec in schema.MESSAGES:
        if spec.key is not None and spec.op == "put":
            out[spec.key] = (spec.name, files[f"{spec.name}.schema.json"].encode())
    return out


class MissionWriter:
    """Writes samples as they came; one thread only (the recorder's writer thread)."""

    def __init__(self, stream: IO[bytes], mission: str, origin: Origin | None, started_ns: int) -> None:
        from mcap.writer import CompressionType, Writer

        from pfp_service import __version__

        self._w = Writer(stream, compression=CompressionType.ZSTD)
        self._w.start(profile=PROFILE, library=f"pfp-service {__version__} (pfp record)")
        self.origin = origin
        self._by_kind = _contract_schemas()
        self._schema_ids: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._keys: dict[str, tuple[int, str, str | None]] = {}  # key -> channel, kind, unit of a state
        self.count = 0
        self.by_kind: dict[str, int] = {}
        meta = {"mission": mission, "started_ns": str(started_ns), "version": __version__}
        if origin is not None:
            meta["origin"] = json.dumps({"lat": origin.lat, "lon": origin.lon, "alt": origin.alt})
        self._w.add_metadata(METADATA, meta)

    def _schema(self, name: str, data: bytes) -> int:
        sid = self._schema_ids.get(name)
        if sid is None:
            sid = self._w.register_schema(name=name, encoding="jsonschema", data=data)
            self._schema_ids[name] = sid
        return sid

    def _channel(self, topic: str, schema_name: str | None, schema: bytes = b"") -> int:
        cid = self._channels.get(topic)
        if cid is None:
            sid = self._schema(schema_name, schema) if schema_name is not None else 0
            cid = self._w.register_channel(topic=topic, message_encoding="json", schema_id=sid)
            self._channels[topic] = cid
        return cid

    def _emit(self, cid: int, t_ns: int, data: bytes, kind: str) -> None:
        self._w.add_message(channel_id=cid, log_time=t_ns, data=data, publish_time=t_ns, sequence=self.count)
        self.count += 1
        self.by_kind[kind] = self.by_kind.get(kind, 0) + 1

    def put(self, key: str, data: bytes, t_ns: int) -> str:
        """A PUT on ``key`` (its payload as it came); returns the key's kind (``other``: unknown)."""
        known = self._keys.get(key)
        if known is None:  # a key's first sample: its kind, schema and channel, once
            try:
                parsed: keys.Key | None = keys.parse(key)
            except InputError:
                parsed = None
            spec = self._by_kind.get(parsed.kind) if parsed is not None else None
            cid = self._channel("/" + key, spec[0] if spec else None, spec[1] if spec else b"")
            kind = parsed.kind.value if parsed is not None else "other"
            fix = parsed.id if parsed is not None and parsed.kind is keys.KeyKind.UNIT_STATE else None
            known = self._keys[key] = (cid, kind, fix)
        cid, kind, fix = known
        self._emit(cid, t_ns, data, kind)
        if self.origin is not None and fix is not None:
            self._fix(fix, data, t_ns)
        return kind

    def _fix(self, unit: str, data: bytes, t_ns: int) -> None:
        try:
            x, y = json.loads(data)["position"][:2]
            assert self.origin is not None
            lat, lon = self.origin.to_geodetic(float(x), float(y))
        except (ValueError, KeyError, TypeError):
            return  # the planner rejects it and the record keeps the state as it came
        fix = {
            "timestamp": {"sec": t_ns // 1_000_000_000, "nsec": t_ns % 1_000_000_000},
            "frame_id": unit,
            "latitude": lat,
            "longitude": lon,
            "altitude": self.origin.alt,
            "position_covariance": [0.0] * 9,
            "position_covariance_type": 0,
        }
        cid = self._channel(FIX_PREFIX + unit, "foxglove.LocationFix", json.dumps(_FIX_SCHEMA).encode())
        self._w.add_message(channel_id=cid, log_time=t_ns, data=json.dumps(fix).encode(), publish_time=t_ns)

    def delete(self, key: str, t_ns: int) -> None:
        cid = self._channel(DELETED_TOPIC, "pfp.deleted", json.dumps(_KEY_SCHEMA).encode())
        self._emit(cid, t_ns, json.dumps({"key": key}).encode(), "deleted")

    def alive(self, key: str, alive: bool, t_ns: int) -> None:
        cid = self._channel(ALIVE_TOPIC, "pfp.alive", json.dumps(_ALIVE_SCHEMA).encode())
        self._emit(cid, t_ns, json.dumps({"key": key, "alive": alive}).encode(), "alive")

    def coverage(self, cov: dict[str, object]) -> None:
        """What the record missed (``Coverage.result``), as metadata ``pfp.coverage``."""
        self._w.add_metadata(COVERAGE, {k: json.dumps(v) for k, v in cov.items()})

    def finish(self) -> None:
        self._w.finish()


@dataclass(frozen=True, slots=True)
class Entry:
    """One recorded sample: when, which key, PUT (``data``) or DELETE (``data`` None)."""

    t_ns: int
    key: str
    data: bytes | None


@dataclass(frozen=True)
class Record:
    """A record's metadata and its samples in log-time order (derived ``/pfp/fix`` topics left out)."""

    mission: str
    origin: Origin | None
    entries: list[Entry]
    alive: list[tuple[int, str, bool]]
    coverage: dict[str, object] | None = None  # None: a record made before pfp.coverage


def read_record(path: str | Path, now_ns: int | None = None) -> Record:
    """Read a whole record, checking every chunk's CRC, within the bounds of ``mcapcheck``.

    The chunks' headers are checked first (``mcapcheck.check_record``); the file is then read in
    order, as checked, and its messages counted against ``mcap_messages``.

    Raises:
        InputError: naming the file: unreadable, not MCAP, damaged, past a bound, or not made by
            ``pfp record``.
    """
    from mcap.exceptions import McapError
    from mcap.records import Channel, Message, Metadata
    from mcap.stream_reader import StreamReader

    from pfp_clients.record.mcapcheck import check_record

    p = Path(path)
    mission, origin = "", None
    coverage: dict[str, object] | None = None
    entries: list[Entry] = []
    alive: list[tuple[int, str, bool]] = []
    topics: dict[int, str] = {}
    most = limit("mcap_messages")
    try:
        with p.open("rb") as f:
            check_record(f, os.fstat(f.fileno()).st_size, p.name)
            f.seek(0)
            reader = StreamReader(f, validate_crcs=True, record_size_limit=limit("mcap_chunk_bytes") + 4096)
            count = 0
            for rec in reader.records:
                if isinstance(rec, Channel):
                    topics[rec.id] = rec.topic
                elif isinstance(rec, Metadata):
                    if rec.name == METADATA:
                        mission = rec.metadata.get("mission", "")
                        if "origin" in rec.metadata:
                            o = json.loads(rec.metadata["origin"])
                            origin = Origin(lat=o["lat"], lon=o["lon"], alt=o.get("alt", 0.0))
                    elif rec.name == COVERAGE:
                        coverage = {k: json.loads(v) for k, v in rec.metadata.items()}
                elif isinstance(rec, Message):
                    count += 1
                    if count > most:
                        raise InputError(p.name, f"holds more than {most:,} messages (mcap_messages)")
                    _take(rec, topics[rec.channel_id], entries, alive)
    except OSError as exc:
        raise InputError(p.name, f"cannot read: {exc.strerror or exc}") from None
    except (McapError, ValueError, KeyError, EOFError, TypeError) as exc:
        raise InputError(p.name, f"not a readable mission record: {exc}") from None
    if not mission:
        raise InputError(p.name, "not a mission record of pfp record (no 'pfp' metadata)")
    entries.sort(key=lambda e: e.t_ns)  # log-time order, stable as the reader's was
    alive.sort(key=lambda a: a[0])
    _check_times(
        p.name, [e.t_ns for e in entries[:1] + entries[-1:]] + [a[0] for a in alive[:1] + alive[-1:]], now_ns
    )
    return Record(mission, origin, entries, alive, coverage)


def _check_times(name: str, ends_ns: list[int], now_ns: int | None) -> None:
    """Refuse log times after ``now_ns`` (plus a clock's slack) or spanning more than ``mcap_span_s``:
    a replay waits out the recorded clock, so a far-future time would hold it until signalled."""
    if not ends_ns:
        return
    now = time.time_ns() if now_ns is None else now_ns
    latest, span_s = max(ends_ns), (max(ends_ns) - min(ends_ns)) / 1e9
    if latest > now + _CLOCK_SLACK_NS:
        when = time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime(min(latest / 1e9, 253402300799)))
        raise InputError(
            name, f"a message's log time ({when}) is in the future; a recorder logs its receipt time"
        )
    if span_s > limit("mcap_span_s"):
        raise InputError(
            name, f"log times span {span_s:,.0f} s; the limit is {limit('mcap_span_s'):,} s (mcap_span_s)"
        )


def _take(msg: Any, topic: str, entries: list[Entry], alive: list[tuple[int, str, bool]]) -> None:
    """One message of the record, into the entries or the liveliness list (derived fixes left out)."""
    if topic == DELETED_TOPIC:
        entries.append(Entry(msg.log_time, json.loads(msg.data)["key"], None))
    elif topic == ALIVE_TOPIC:
        a = json.loads(msg.data)
        alive.append((msg.log_time, a["key"], bool(a["alive"])))
    elif not topic.startswith(FIX_PREFIX):
        entries.append(Entry(msg.log_time, topic.lstrip("/"), bytes(msg.data)))


def iter_kind(rec: Record, kind: keys.KeyKind) -> Iterator[tuple[Entry, keys.Key]]:
    """The record's samples on keys of ``kind``, with the parsed key."""
    for e in rec.entries:
        try:
            k = keys.parse(e.key)
        except InputError:
            continue
        if k.kind is kind:
            yield e, k
