"""``pfp report``: an after-action summary of a mission record.

Per unit: its track (every state it reported), its time (first report to the
planner's ``arrived``, or to its last report), its path length, its exposure
and closest approach to a threat (measured on the track under the threats in
force when each segment was walked, as ``pfp demo`` measures), the replans that
named it and what caused them (the threat and zone changes of each
``event/replan``), escapes and traps.  Times are the units' own clocks when
every state carries its ``t`` (``pfp fleet``'s simulated seconds, at any
``--speed-up``), else seconds of the record's wall clock; the report says which.

Out: the table on stdout and as CSV, a PNG of the threats and tracks, and,
when the record knows the mission origin, GeoJSON (RFC 7946, WGS-84) of every
track with its row of the table, and of the threats.  The PNG draws the
keep-out zones in force at the end, a threat that appeared after the units
set out in orange with when it appeared, and, with an origin, lat/lon axes.

With a DEM (``ground``: ``pfp report --terrain``), each unit also gets its
climb, the steepest ground it crossed and its seconds in view of each threat
(``report_terrain``): three more columns, and the same figures in each track's
GeoJSON properties, under a ``terrain`` member that says how they were measured.

With teams in the record, a second table (and ``STEM.teams.csv``): each team's
closest two members and its robots' link outages, each listed with its cause
(``report_teams``).
"""

from __future__ import annotations

import collections
import csv
import json
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgspec
import numpy as np

from pfp_clients.record.mcapfile import Record
from pfp_clients.record.report_teams import team_rows
from pfp_clients.watch import Watch
from pfp_service.coords import Coords
from pfp_service.errors import InputError
from pfp_service.wire import ThreatUpdate, keys
from pfp_service.world import translate

__all__ = ["UnitSummary", "clock_name", "popups", "summarise", "table_rows", "write_report", "zones_at_end"]

COLUMNS = ("unit", "status", "time s", "path m", "exposure", "min clear m", "replans", "causes")


@dataclass
class UnitSummary:
    """One unit's mission, from the record."""

    unit: str
    track: list[tuple[float, float, float]] = field(default_factory=list)  # (t_s, x, y)
    status: str = "-"
    arrived_s: float | None = None
    replans: int = 0
    causes: collections.Counter[str] = field(default_factory=collections.Counter)
    escapes: int = 0
    length_m: float = 0.0
    exposure: float | None = None
    min_clearance_m: float = math.inf
    seqs: list[int] = field(default_factory=list)  # its states' seq, as recorded
    clock: list[tuple[float, float]] = field(default_factory=list)  # (record s, the state's own t)

    @property
    def own_clock(self) -> bool:
        """Every state carried its ``t``: times are the unit's (simulated, under ``pfp fleet``)."""
        return bool(self.track) and len(self.clock) == len(self.track)

    @property
    def time_s(self) -> float | None:
        if not self.track:
            return None
        end = self.arrived_s if self.arrived_s is not None else self.track[-1][0]
        if self.own_clock:  # the unit's time at its last report by then
            seen = [t for rec_s, t in self.clock if rec_s <= end] or [self.clock[0][1]]
            return seen[-1] - self.clock[0][1]
        return end - self.track[0][0]


def _natural(uid: str) -> list[Any]:
    """Ids as people sort them: m2 before m10."""
    return [(0, int(p), "") if p.isdigit() else (1, 0, p) for p in re.split(r"(\d+)", uid) if p]


def _changes(ev: dict[str, Any]) -> list[str]:
    out = []
    for c in ev.get("changes", []) or []:
        what = c.get("threat") or c.get("zone") or "?"
        out.append(f"{c.get('change', 'changed')} {what}")
    if ev.get("more"):
        out.append(f"{ev['more']} more changes")
    return out or [str(ev.get("reason") or "replan")]


def summarise(rec: Record, intensity: str = "peak") -> tuple[list[UnitSummary], Watch]:
    """Each unit's summary (natural order of ids), and the threat history, from ``rec``."""
    from pfp_service.core.metrics import measure

    t0 = rec.entries[0].t_ns if rec.entries else 0
    units: dict[str, UnitSummary] = {}
    watch = Watch()
    threat_decoder = msgspec.json.Decoder(ThreatUpdate)

    def unit(uid: str) -> UnitSummary:
        return units.setdefault(uid, UnitSummary(uid))

    for e in rec.entries:
        t_s = (e.t_ns - t0) / 1e9
        try:
            k = keys.parse(e.key)
        except InputError:
            continue
        kind = k.kind.value
        if e.data is None:
            if k.kind is keys.KeyKind.THREAT:
                watch.threat_removed(k.id, t_s)
            continue
        try:
            if k.kind is keys.KeyKind.THREAT:
                watch.threat_put(k.id, threat_decoder.decode(e.data), t_s)
                continue
            d = json.loads(e.data)
        except (
            msgspec.ValidationError,
            msgspec.DecodeError,
            ValueError,
        ):  # rejected by the planner: kept, not summed
            continue
        if not isinstance(d, dict):
            continue
        if kind.endswith("state"):
            pos = d.get("position")
            if isinstance(pos, list) and len(pos) >= 2:
                unit(k.id).track.append((t_s, float(pos[0]), float(pos[1])))
                if isinstance(d.get("t"), int | float):
                    unit(k.id).clock.append((t_s, float(d["t"])))
            if isinstance(d.get("seq"), int):
                unit(k.id).seqs.append(d["seq"])
        elif k.kind is keys.KeyKind.UNIT_DIRECTION:
            u = unit(k.id)
            status = str(d.get("status"))
            if status == "escaping" and u.status != "escaping":
                u.escapes += 1
            u.status = status
            if status == "arrived" and u.arrived_s is None:
                u.arrived_s = t_s
            elif status in ("en_route", "escaping"):
                u.arrived_s = None  # a new goal after an arrival: the time runs to the next one
        elif k.kind is keys.KeyKind.EVENT:
            ev_kind = d.get("kind")
            if ev_kind == "replan":
                causes = _changes(d)
                for uid in d.get("units", []) or []:
                    u = unit(uid)
                    u.replans += 1
                    u.causes.update(causes)
            elif ev_kind == "arrived" and d.get("unit"):
                u = unit(d["unit"])
                if u.arrived_s is None:
                    u.arrived_s = t_s
            elif ev_kind == "trapped" and d.get("unit"):
                unit(d["unit"]).causes.update(["trapped: " + str(d.get("reason", ""))[:60]])
    for u in units.values():
        if len(u.track) < 2:
            continue
        path = np.array([(x, y) for _t, x, y in u.track], dtype=float)
        epochs = [ep for ep, _ in watch.epochs([t for t, _x, _y in u.track], intensity)]
        m = measure(path, epochs)
        u.length_m, u.exposure, u.min_clearance_m = m.length, m.exposure, m.min_clearance
    return sorted(units.values(), key=lambda u: _natural(u.unit)), watch


def table_rows(rows: list[UnitSummary]) -> list[tuple[str, ...]]:
    out: list[tuple[str, ...]] = [COLUMNS]
    for u in rows:
        t = u.time_s
        causes = "; ".join(f"{c} x{n}" if n > 1 else c for c, n in u.causes.most_common(4)) or "-"
        out.append(
            (
                u.unit,
                u.status,
                "-" if t is None else f"{t:.1f}",
                f"{u.length_m:.1f}",
                "-" if u.exposure is None else f"{u.exposure:.3f}",
                "inf" if math.isinf(u.min_clearance_m) else f"{u.min_clearance_m:.2f}",
                str(u.replans),
                causes,
            )
        )
    return out


def clock_name(rows: list[UnitSummary]) -> str:
    """Which clock the times are on: the units' own (every state carried ``t``) or the record's."""
    tracked = [u for u in rows if u.track]
    if tracked and all(u.own_clock for u in tracked):
        return "the units' own clocks (each state's t: simulated seconds under pfp fleet)"
    return "the record's wall clock (the states carry no t)"


def popups(rows: list[UnitSummary], watch: Watch) -> dict[str, str]:
    """Threat id -> ``"appeared at 312 s"`` for each threat first put after the first unit's first report.

    On the units' clocks when they all have one (the record's seconds mapped onto theirs), so the
    figure agrees with the table.
    """
    starts = [u.track[0][0] for u in rows if u.track]
    if not starts:
        return {}
    first: dict[str, float] = {}
    for v in watch.versions:
        first.setdefault(v.threat_id, v.start_s)
    pairs = sorted(p for u in rows if u.own_clock for p in u.clock)
    own = bool(pairs) and all(u.own_clock for u in rows if u.track)
    out = {}
    for tid, t in first.items():
        if t > min(starts):
            at = float(np.interp(t, [r for r, _ in pairs], [c for _, c in pairs])) if own else t
            out[tid] = f"appeared at {at:.0f} s"
    return out


def zones_at_end(rec: Record) -> list[Any]:
    """The keep-out zones in force when the record ends (each put and not since removed), as core ``Zone``s."""
    from pfp_service.wire.messages import decode_zone
    from pfp_service.world import translate

    held: dict[str, Any] = {}
    for e in rec.entries:
        try:
            k = keys.parse(e.key)
        except InputError:
            continue
        if k.kind is not keys.KeyKind.ZONE:
            continue
        if e.data is None:
            held.pop(k.id, None)
            continue
        try:
            held[k.id] = translate.zone(decode_zone(e.data, None, rec.origin), k.id)
        except (InputError, ValueError):  # refused by the planner too: not in force
            continue
    return list(held.values())


def _text(rows: list[tuple[str, ...]]) -> list[str]:
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return ["  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows]


def _geojson(
    rec: Record, rows: list[UnitSummary], watch: Watch, table: list[tuple[str, ...]], ground: dict[str, Any]
) -> dict[str, Any]:
    assert rec.origin is not None
    o = rec.origin
    feats: list[dict[str, Any]] = []
    for u, row in zip(rows, table[1:]):
        if not u.track:
            continue
        xy = np.array([(x, y) for _t, x, y in u.track], dtype=float)
        ll = o.to_geodetic_many(xy)  # (n, 2) lat, lon
        coords = [[round(float(lon), 8), round(float(lat), 8)] for lat, lon in ll]
        geom = {"type": "LineString", "coordinates": coords if len(coords) > 1 else coords * 2}
        props: dict[str, Any] = dict(zip(table[0], row))
        props["kind"] = "track"
        if u.unit in ground.get("units", {}):
            props.update(ground["units"][u.unit])
        feats.append({"type": "Feature", "geometry": geom, "properties": props})
    for v in watch.versions:
        lat, lon = o.to_geodetic(*v.update.position)
        feats.append(
            {
                "type": "Feature",
                "geometry": {"type": "Point", "coordinates": [round(lon, 8), round(lat, 8)]},
                "properties": {
                    "kind": "threat",
                    "id": v.threat_id,
                    "from_s": round(v.start_s, 2),
                    "until_s": None if math.isinf(v.end_s) else round(v.end_s, 2),
                    "shape": v.update.shape,
                    **translate.shape_params(v.update),
                },
            }
        )
    out: dict[str, Any] = {"type": "FeatureCollection", "features": feats}
    if ground:  # a foreign member (RFC 7946 section 6.1): how the terrain figures were measured
        out["terrain"] = ground["about"]
    return out


def write_report(
    rec: Record, stem: Path, intensity: str = "peak", say: Any = print, ground: tuple[str, Any] | None = None
) -> list[Path]:
    """Print the table and write ``STEM.csv``, ``STEM.png`` and (with an origin) ``STEM.geojson``.

    Args:
        ground: a DEM's path and the unit class (``core.mobility.Mobility``) to measure the tracks for.

    Raises:
        InputError: a file cannot be written; the DEM (its path) cannot be read or does not cover the record.
    """
    from pfp_clients.record.coverage import describe, describe_gaps, seq_gaps
    from pfp_service.render import plot_tracks

    rows, watch = summarise(rec, intensity)
    table = table_rows(rows)
    say(f"mission {rec.mission}: {len(rows)} units, {len(watch.versions)} threat versions")
    if rec.coverage is not None:
        say(f"record: {describe(rec.coverage)}")
    say(f"record: {describe_gaps({u.unit: seq_gaps(u.seqs) for u in rows if u.seqs})}")
    clock = clock_name(rows)
    say(f"times (time s): {clock}")
    over: dict[str, Any] = {}
    if ground is not None:
        over = _over_ground(rec, rows, watch, clock, ground, table)
        say(over["about"]["says"])
    for line in _text(table):
        say(line)
    teams, outages = team_rows(rec, {u.unit: u.track for u in rows})
    if len(teams) > 1:  # per team: its closest two members, and its robots' link outages with their cause
        say("")
        for line in [
            *_text(teams),
            *(f"  {o.robot} out of link {o.start_s:.1f}-{o.end_s:.1f} s: {o.cause}" for o in outages),
        ]:
            say(line)
    written: list[Path] = []
    csv_path = stem.with_suffix(".csv")
    png = stem.with_suffix(".png")
    try:
        with csv_path.open("w", newline="") as f:
            csv.writer(f).writerows(table)
        written.append(csv_path)
        if len(teams) > 1:
            with stem.with_suffix(".teams.csv").open("w", newline="") as f:
                csv.writer(f).writerows(teams)
            written.append(stem.with_suffix(".teams.csv"))
        latest: dict[str, Any] = {}
        first: dict[str, Any] = {}
        for v in watch.versions:
            latest[v.threat_id] = v.threat()
            first.setdefault(v.threat_id, v.threat())
        moved = [(first[t], latest[t]) for t in latest if first[t].xi != latest[t].xi]
        tracks: dict[str, Sequence[Sequence[float]]] = {
            u.unit: [(x, y) for _t, x, y in u.track] for u in rows if u.track
        }
        goals: dict[str, Sequence[float]] = {
            u.unit: u.track[-1][1:] for u in rows if u.track and u.arrived_s is not None
        }
        arrived = sum(u.arrived_s is not None for u in rows)
        simulated = "simulated" if clock.startswith("the units'") else "wall-clock"
        plot_tracks(
            list(latest.values()),
            intensity,
            tracks,
            goals,
            png,
            title=f"mission {rec.mission}: {arrived}/{len(rows)} arrived, "
            f"{sum(u.replans for u in rows)} replans (times in {simulated} seconds)",
            old_threats=moved,
            coords=Coords.choose("latlon", rec.origin) if rec.origin is not None else None,
            zones=zones_at_end(rec),
            popups=popups(rows, watch),
        )
        written.append(png)
        if rec.origin is not None:
            gj = stem.with_suffix(".geojson")
            gj.write_text(json.dumps(_geojson(rec, rows, watch, table, over)))
            written.append(gj)
    except OSError as exc:
        raise InputError(str(stem.parent), f"cannot write the report: {exc.strerror or exc}") from None
    for p in written:
        say(f"wrote {p}")
    if rec.origin is None:
        say("no GeoJSON: the record has no origin (the planner had none when recording started)")
    return written


def _over_ground(
    rec: Record,
    rows: list[UnitSummary],
    watch: Watch,
    clock: str,
    ground: tuple[str, Any],
    table: list[tuple[str, ...]],
) -> dict[str, Any]:
    """Each unit's climb, steepest ground and time in view, added to ``table`` (in place) and returned."""
    from pfp_clients.record.report_terrain import load, measure_ground

    path, unit = ground
    if rec.origin is None:
        raise InputError("--terrain", "the record has no origin: its metres cannot be placed on a DEM")
    points = [(x, y) for u in rows for _t, x, y in u.track] + [v.update.position for v in watch.versions]
    if not points:
        return {}
    terrain = load(path, rec.origin, points, unit)
    own = clock.startswith("the units'")
    times = {u.unit: [c for _r, c in u.clock] if own else [t for t, _x, _y in u.track] for u in rows}
    got = measure_ground(terrain, {u.unit: u.track for u in rows}, times, watch)
    table[0] = (*table[0], "climb m", "max slope deg", "in view s")
    units = {}
    for i, u in enumerate(rows, start=1):
        g = got[u.unit]
        seen = "; ".join(f"{t} {s:.1f}" for t, s in sorted(g.in_view_s.items()) if s > 0) or "-"
        slope = "-" if g.max_slope_deg is None else f"{g.max_slope_deg:.1f}"
        table[i] = (*table[i], f"{g.climb_m:.1f}", slope, seen)
        units[u.unit] = {
            "climb_m": round(g.climb_m, 2),
            "max_slope_deg": None if g.max_slope_deg is None else round(g.max_slope_deg, 2),
            "in_view_s": {t: round(s, 2) for t, s in sorted(g.in_view_s.items())},
        }
    cell = terrain.grid.cell_m
    says = (
        f"terrain: {Path(path).name} at {cell:.0f} m cells, for a {unit.kind} unit {unit.height_m:g} m tall: "
        "climb (every rise summed), max slope (of the ground crossed), in view s (per threat, a clear "
        "line of sight from its eye to the unit within its reach)"
    )
    about = {
        "dem": Path(path).name,
        "cell_m": round(cell, 2),
        "unit_class": unit.kind,
        "unit_height_m": unit.height_m,
        "says": says,
    }
    return {"units": units, "about": about}
