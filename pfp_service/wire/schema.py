"""The published contract: JSON Schema, examples and the key of every wire message (``contract.MESSAGES``).

``render(supplied)`` returns the whole ``schemas/`` directory as ``{relative path: text}``
from the Structs themselves and their specs, so it cannot drift from the code.  The wire imports no
core, so a message whose type is the core's (the preview reply, ``PlanResult``) has
no type in ``MESSAGES``: a higher layer supplies it and its examples
(``world.translate.supplied()``).  ``diff()`` says what on disk is stale and
``write()`` brings it up to date; ``pfp schemas [--check]`` calls them.  Only
``diff`` and ``write`` touch the file system.
"""

from __future__ import annotations

import inspect
import json
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgspec

from pfp_service.geo import POSITION_FIELDS, LatLon
from pfp_service.wire import keys
from pfp_service.wire import messages as m
from pfp_service.wire.contract import LIVELINESS, MESSAGES, MessageSpec, examples

__all__ = [
    "CONTRACT_VERSION",
    "LIVELINESS",
    "MESSAGES",
    "MessageSpec",
    "Supplied",
    "diff",
    "render",
    "write",
]

# Bumped only for a change an older client cannot read; adding a defaulted field is not one.
CONTRACT_VERSION = 1
JSON_SCHEMA_DIALECT = "https://json-schema.org/draft/2020-12/schema"


@dataclass(frozen=True)
class Supplied:
    """A message of the contract whose type the wire cannot name (its ``MessageSpec.type`` is None):
    the type and its ``(example name, instance)`` pairs, given to ``render`` by a higher layer."""

    type: Any
    examples: tuple[tuple[str, Any], ...]


def _dump(obj: Any) -> str:
    return json.dumps(obj, indent=2, ensure_ascii=False) + "\n"


def _describe(defs: dict[str, Any]) -> None:
    """Dedent each struct's docstring and move its ``Attributes:`` lines onto the properties."""
    for d in defs.values():
        if "description" not in d:
            continue
        doc, _, attrs = inspect.cleandoc(d["description"]).partition("\nAttributes:\n")
        d["description"] = doc.strip()
        name = ""
        notes: dict[str, str] = {}
        for line in attrs.splitlines():
            head, sep, text = line.strip().partition(": ")
            if sep and head.isidentifier() and line.startswith("    ") and not line.startswith("        "):
                name = head
                notes[name] = text.strip()
            elif name:
                notes[name] += " " + line.strip()
        for field, text in notes.items():
            prop = d.get("properties", {}).get(field)
            if prop is not None:
                d["properties"][field] = {"description": text, **prop}


GEODETIC_NOTE = (
    "A position is [x, y] metres east and north of the mission origin, or "
    '{"lat": …, "lon": …} in WGS-84 degrees (the planner needs a mission origin for that).'
)


def _either_form(prop: dict[str, Any]) -> dict[str, Any]:
    """A point's schema widened to ``point | LatLon`` (keeping null if it was allowed)."""
    ref = {"$ref": "#/$defs/LatLon"}
    note = {"description": prop["description"]} if "description" in prop else {}
    if prop.get("type") == "array":
        return {**note, "anyOf": [{k: v for k, v in prop.items() if k != "description"}, ref]}
    alts = prop.get("anyOf")
    if alts and any(a.get("type") == "array" for a in alts):
        return {**prop, "anyOf": [*alts, ref]}
    return prop


def _geodetic_positions(spec: MessageSpec, body: dict[str, Any]) -> None:
    """Messages to the planner take lat/lon wherever they take a position (``geo.POSITION_FIELDS``)."""
    if spec.receiver != "planner":
        return
    defs = body.setdefault("$defs", {})
    for d in list(defs.values()):
        props = d.get("properties", {})
        for name in POSITION_FIELDS & props.keys():
            props[name] = _either_form(props[name])
        if POSITION_FIELDS & props.keys():
            d["description"] = f"{d.get('description', '').rstrip()}\n\n{GEODETIC_NOTE}".lstrip()
    _geodetic_zone(defs)
    defs.update(msgspec.json.schema(LatLon)["$defs"])


def _geodetic_zone(defs: dict[str, Any]) -> None:
    """A zone's polygon vertices and circle centre take lat/lon too (``codec._localise_zone``)."""
    polygon = defs.get("ZoneUpdate", {}).get("properties", {}).get("polygon")
    if polygon is not None:
        for alt in polygon.get("anyOf", [polygon]):
            ring = alt.get("items") if alt.get("type") == "array" else None
            if ring is not None and "items" in ring:
                ring["items"] = _either_form(ring["items"])
    centre = defs.get("ZoneCircle", {}).get("properties", {}).get("centre")
    if centre is not None:
        defs["ZoneCircle"]["properties"]["centre"] = _either_form(centre)
        defs["ZoneCircle"]["description"] += "\n\n" + GEODETIC_NOTE


def _schema(spec: MessageSpec, supplied: Mapping[str, Supplied]) -> dict[str, Any]:
    body = msgspec.json.schema(supplied[spec.name].type if spec.type is None else spec.type)
    _describe(body.get("$defs", {}))
    _geodetic_positions(spec, body)
    head: dict[str, Any] = {
        "$schema": JSON_SCHEMA_DIALECT,
        "$id": f"{spec.name}.schema.json",
        "title": spec.name,
    }
    info: dict[str, Any] = {"op": spec.op, "from": spec.sender, "to": spec.receiver}
    if spec.key is not None:
        info["key"] = keys.template(spec.key)
    if spec.note:
        info["note"] = spec.note
    head["x-pfp"] = info
    return {**head, **body}


def _index(ex: dict[str, list[tuple[str, Any]]]) -> dict[str, Any]:
    msgs: dict[str, Any] = {}
    for spec in MESSAGES:
        entry: dict[str, Any] = {"key": keys.template(spec.key) if spec.key is not None else None}
        entry.update(op=spec.op, sender=spec.sender, receiver=spec.receiver)
        if spec.note:
            entry["note"] = spec.note
        entry["schema"] = f"{spec.name}.schema.json"
        entry["examples"] = [f"examples/{name}.json" for name, _ in ex[spec.name]]
        msgs[spec.name] = entry
    return {
        "contract": "pfp-service wire contract",
        "version": CONTRACT_VERSION,
        "encoding": m.CONTENT_TYPE,
        "max_payload_bytes": m.MAX_PAYLOAD_BYTES,
        "default_mission": keys.DEFAULT_MISSION,
        "chunk_pattern": keys.CHUNK_PATTERN,
        "evolution": "fields are only added, always with a default; readers ignore unknown fields",
        "messages": msgs,
        "liveliness": {k.value: keys.template(k) for k in LIVELINESS},
        "shards": {
            "key": keys.SHARD_STATE_TEMPLATE,
            "count": keys.SHARDS,
            "shard": f"crc32(utf8(unit)) % {keys.SHARDS}, CRC-32 as zlib's (ISO-HDLC); decimal, no leading zeros",
            "test_vectors": {u: keys.shard_of(u) for u in ("ugv-1", "u0", "u1")},
        },
    }


def _readme(index: dict[str, Any]) -> str:
    lines = [
        "# pfp-service wire contract (generated by `pfp schemas`; do not edit)",
        "",
        f"Contract version {index['version']}. Every payload is JSON (`{index['encoding']}`), at most "
        f"{index['max_payload_bytes']} bytes. `{{mission}}` defaults to `{index['default_mission']}`; "
        f"every `{{...}}` chunk matches `{index['chunk_pattern']}`. {index['evolution'].capitalize()}.",
        "",
        "| message | key | op | from → to | schema | example |",
        "|---|---|---|---|---|---|",
    ]
    for name, e in index["messages"].items():
        key = f"`{e['key']}`" if e["key"] else "(reply to a query)"
        exs = ", ".join(f"[{Path(x).stem}]({x})" for x in e["examples"])
        note = f" — {e['note']}" if "note" in e else ""
        lines.append(
            f"| {name}{note} | {key} | {e['op']} | {e['sender']} → {e['receiver']} | "
            f"[{e['schema']}]({e['schema']}) | {exs} |"
        )
    lines += ["", "Liveliness tokens (no payload):", ""]
    lines += [f"- `{t}`" for t in index["liveliness"].values()]
    sh = index["shards"]
    vectors = ", ".join(f"`{u}` → {s}" for u, s in sh["test_vectors"].items())
    lines += [
        "",
        f"A unit state may also go on its shard key, `{sh['key']}`, with `{{shard}}` = {sh['shard']} "
        f"(test vectors: {vectors}). Under `--cluster` each planner subscribes to its own shards only; "
        "every planner also reads the plain key. Publish on one of the two, not both.",
    ]
    lines += ["", "Machine-readable: [index.json](index.json).", ""]
    return "\n".join(lines)


def render(supplied: Mapping[str, Supplied]) -> dict[str, str]:
    """Every file of ``schemas/`` as ``{relative posix path: text}``.

    Args:
        supplied: by message name, the type and examples of each message whose type the wire
            cannot name (``world.translate.supplied()``).

    Raises:
        ValueError: ``supplied`` does not name exactly those messages.
    """
    wanted = {spec.name for spec in MESSAGES if spec.type is None}
    if supplied.keys() != wanted:
        raise ValueError(f"supplied: expected the messages {sorted(wanted)}, got {sorted(supplied)}")
    ex = examples() | {name: list(s.examples) for name, s in supplied.items()}
    files: dict[str, str] = {}
    for spec in MESSAGES:
        files[f"{spec.name}.schema.json"] = _dump(_schema(spec, supplied))
        for name, obj in ex[spec.name]:
            files[f"examples/{name}.json"] = _dump(msgspec.to_builtins(obj))
    index = _index(ex)
    files["index.json"] = _dump(index)
    files["README.md"] = _readme(index)
    return files


def _on_disk(directory: Path) -> set[str]:
    if not directory.is_dir():
        return set()
    return {
        p.relative_to(directory).as_posix()
        for p in directory.rglob("*")
        if p.is_file() and p.suffix in (".json", ".md")
    }


def diff(directory: Path, files: dict[str, str]) -> list[str]:
    """What is stale in ``directory`` against ``files`` (``render``'s): ``missing X``, ``changed X`` and ``extra X`` lines."""
    out: list[str] = []
    present = _on_disk(directory)
    for rel, text in sorted(files.items()):
        if rel not in present:
            out.append(f"missing {rel}")
        elif (directory / rel).read_text(encoding="utf-8") != text:
            out.append(f"changed {rel}")
    out += [f"extra {rel}" for rel in sorted(present - files.keys())]
    return out


def write(directory: Path, files: dict[str, str], log: Callable[[str], None] | None = None) -> list[str]:
    """Bring ``directory`` up to ``files`` (``render``'s) and return what changed (as ``diff`` names it)."""
    changes = diff(directory, files)
    for line in changes:
        what, rel = line.split(" ", 1)
        path = directory / rel
        if what == "extra":
            path.unlink()
        else:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(files[rel], encoding="utf-8")
        if log is not None:
            log(line)
    return changes
