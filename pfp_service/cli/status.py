"""``pfp status``: list what each planner of the mission holds: its units, threats, keep-out zones and teams.

Asks the world queryable (``mumt/{m}/planner/*/world``) and the status of
every planner.  Without ``--json``, a table of the live planners first (units
owned, threats and zones in force, latency, deliberations, overload: several
share a mission under ``--cluster``), then up to four tables per planner:
units (id, kind, phase, status, last seen, distance to goal, position), threats (id,
position, TTL left), teams (id, lead, follow, controller, robots, other
members, then what each team's roles last said of a member: held, redirected,
link lost) and keep-out zones (id, kind, shape, centroid, TTL left),
ids in natural order (m2 before m10).  Positions are lat/lon with the metres
from the origin when the planner has one (``--coords`` chooses: latlon,
metres, mgrs).  With ``--json``, one JSON array of every planner's full
``WorldSnapshot``: every page of it, merged (``service.worldpages.whole_world``);
the tables show a planner's first page (up to 1,000 units and threats, and the
zones that fit) and count the rest.
Exit codes: 0 a planner answered; 1 none did; 2 a bad flag.
"""

from __future__ import annotations

import argparse
import contextlib
from collections.abc import Sequence
from typing import Any

from pfp_service.cli._common import add_coords_arg, add_session_args, positive_float, session_config
from pfp_service.coords import Coords
from pfp_service.natsort import natural_key

# the help's example line (cli.build_parser puts it under the parser)
EXAMPLES = {"status": "pfp status --mission exercise1 --coords mgrs"}


def register(sub: Any) -> None:
    p = sub.add_parser(
        "status", help="list the units, threats and keep-out zones a planner holds", description=__doc__
    )
    add_session_args(p)
    p.add_argument(
        "--timeout", type=positive_float, default=2.0, metavar="S", help="seconds to wait for answers"
    )
    p.add_argument("--json", action="store_true", help="print a JSON array of every planner's full snapshot")
    add_coords_arg(p)
    p.set_defaults(func=run)


def _table(rows: Sequence[Sequence[str]]) -> list[str]:
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return ["  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows]


def _num(value: float | None, unit: str = "", digits: int = 1) -> str:
    return "-" if value is None else f"{value:.{digits}f}{unit}"


def planner_lines(statuses: Sequence[Any]) -> list[str]:
    """The live planners as a table: who guides how many units, how fast, and how loaded."""
    rows: list[tuple[str, ...]] = [
        ("planner", "owns", "units", "stale", "threats", "zones", "p50", "p99", "deliberating", "overload")
    ]
    ids = [st.planner for st in statuses]
    for st in statuses:
        rows.append(
            (
                # planners sharing an id (a conflict) are told apart by their Zenoh session
                f"{st.planner} ({st.session})" if ids.count(st.planner) > 1 else st.planner,
                str(st.units_owned),
                str(st.units),
                str(st.units_stale),
                str(st.threats),
                str(st.zones),
                _num(st.latency_p50_ms, " ms", 2),
                _num(st.latency_p99_ms, " ms", 2),
                str(st.deliberating),
                str(st.overload),
            )
        )
    return _table(rows)


def zone_shape(update: Any) -> str:
    """A zone's shape in words: ``polygon, 5 vertices, 1 hole`` or ``circle, radius 25.0 m``."""
    if update.circle is not None:
        return f"circle, radius {update.circle.radius_m:.1f} m"
    shell, *holes = update.polygon
    text = f"polygon, {len(shell) - 1} vertices"
    if holes:
        text += f", {len(holes)} hole" + ("s" if len(holes) > 1 else "")
    return text


def zone_centroid(update: Any) -> tuple[float, float]:
    """Where a zone lies: a circle's centre, a polygon's centroid (its holes left out), in metres."""
    if update.circle is not None:
        cx, cy = update.circle.centre
        return float(cx), float(cy)
    import shapely

    shell, *holes = update.polygon
    c = shapely.Polygon(shell, holes).centroid
    return float(c.x), float(c.y)


def _shape(update: Any) -> str:
    """The threat's shape and its first parameter (a skew-normal's facing, an area's radius)."""
    from pfp_service.world import translate

    try:
        rows = translate.describe(update)
    except ValueError:  # a shape this command does not know: its name alone
        return str(update.shape)
    return " ".join(value for _, value in rows[:2])


def _ttl(ttl_s: float | None) -> str:
    return "no expiry" if ttl_s is None else f"{ttl_s:.1f} s"


def snapshot_lines(snap: Any, coords: Coords | None = None) -> list[str]:
    """One planner's snapshot as text: a heading, then the units, threats and keep-out zones tables.

    Args:
        snap: the planner's ``WorldSnapshot``.
        coords: how positions are shown (default: metres).
    """
    coords = coords or Coords()
    lines = [
        f"planner {snap.planner}, mission {snap.mission}: {snap.units_total} units, "
        f"{snap.threats_total} threats, {snap.zones_total} zones"
        + (f", {snap.teams_total} teams" if getattr(snap, "teams_total", 0) else "")
    ]
    if snap.units:
        rows: list[tuple[str, ...]] = [
            ("unit", "kind", "phase", "status", "last seen", "to goal", "position")
        ]
        units = sorted(snap.units, key=lambda u: natural_key(u.id))
        placed = iter(coords.points([u.position for u in units if u.position is not None]))
        for u in units:
            status = "stale" if u.stale else (u.status.value if u.status is not None else "-")
            if u.deliberating:
                status += " (deliberating)"
            pos = "-" if u.position is None else next(placed)
            rows.append(
                (
                    u.id,
                    u.kind.value if u.kind is not None else "-",
                    u.phase.value if u.phase is not None else "-",  # an older planner says none
                    status,
                    _num(u.last_seen_s, " s ago"),
                    _num(u.distance_to_goal, " m"),
                    pos,
                )
            )
        lines += ["", *_table(rows)]
        if snap.units_total > len(snap.units):
            lines.append(f"... and {snap.units_total - len(snap.units)} more units (--json lists them all)")
    if snap.threats:
        rows = [("threat", "position", "shape", "TTL left")]
        threats = sorted(snap.threats, key=lambda t: natural_key(t.id))
        for t, pos in zip(threats, coords.points([t.threat.position for t in threats])):
            rows.append((t.id, pos, _shape(t.threat), _ttl(t.ttl_s)))
        lines += ["", *_table(rows)]
        if snap.threats_total > len(snap.threats):
            lines.append(
                f"... and {snap.threats_total - len(snap.threats)} more threats (--json lists them all)"
            )
    lines += team_lines(snap)
    if snap.zones:
        rows = [("zone", "kind", "shape", "centroid", "TTL left")]
        zones = sorted(snap.zones, key=lambda z: natural_key(z.id))
        for z, pos in zip(zones, coords.points([zone_centroid(z.zone) for z in zones])):
            rows.append((z.id, z.zone.kind, zone_shape(z.zone), pos, _ttl(z.ttl_s)))
        lines += ["", *_table(rows)]
        if snap.zones_total > len(snap.zones):
            lines.append(f"... and {snap.zones_total - len(snap.zones)} more zones (--json lists them all)")
    return lines


def team_lines(snap: Any) -> list[str]:
    """The teams table (team, lead, follow, controller, robots) and what each team's roles last said."""
    teams = getattr(snap, "teams", [])
    if not teams:
        return []
    rows: list[tuple[str, ...]] = [("team", "lead", "follow", "controller", "robots", "other members")]
    notes: list[str] = []
    for t in sorted(teams, key=lambda t: natural_key(t.id)):
        m = t.team
        roled = {m.lead, *m.follow, m.controller, *m.robots}
        others = [u for u in m.members if u not in roled]
        rows.append(
            (t.id, m.lead or "-", " ".join(m.follow) or "-", m.controller or "-", " ".join(m.robots) or "-",
             " ".join(others) or "-")
        )  # fmt: skip
        notes += [f"  {t.id}: {n}" for n in t.notes]
        slowest = getattr(t, "slowest", None)  # null from an older planner
        if slowest is not None:
            eta = "unknown" if t.eta_s is None else f"{t.eta_s:,.0f} s"
            why = f"{slowest} not moving" if t.eta_s is None else slowest
            notes.append(f"  {t.id}: ETA {eta} ({why})")
    lines = ["", *_table(rows), *notes]
    if snap.teams_total > len(teams):
        lines.append(f"... and {snap.teams_total - len(teams)} more teams (--json lists those that fit)")
    return lines


def _coords(args: argparse.Namespace, origin: Any) -> Coords:
    """``--coords`` for one planner: its origin, when it has one; a planner without shows metres."""
    import sys

    if args.coords not in (None, "metres") and origin is None:
        print(f"pfp status: --coords {args.coords}: the planner has no origin; its positions are in metres",
              file=sys.stderr)  # fmt: skip
    return Coords.choose(args.coords, origin, strict=False)


def _whole(session: Any, args: argparse.Namespace, first: Any) -> Any:
    """Every page of one planner's world after ``first``; a line on stderr if it stopped short."""
    import sys

    from pfp_service.node.worldpages import whole_world

    def ask(selector: str, timeout_s: float) -> list[bytes]:
        return [r.ok.payload.to_bytes() for r in session.get(selector, timeout=timeout_s) if r.ok is not None]

    merged, complete = whole_world(ask, args.mission, first, page_timeout_s=args.timeout)
    if not complete:
        print(
            f"pfp status: planner {first.planner}: stopped after {len(merged.units)} units, "
            f"{len(merged.threats)} threats and {len(merged.zones)} zones "
            f"(of {merged.units_total}, {merged.threats_total} and {merged.zones_total})",
            file=sys.stderr,
        )
    return merged


def run(args: argparse.Namespace) -> int:
    import sys

    import msgspec
    import zenoh

    from pfp_service.cli.health import duplicate_warnings
    from pfp_service.errors import InputError, Unreachable, map_zenoh_errors
    from pfp_service.wire import decode_planner_status, decode_world_snapshot, keys

    conf = session_config(args)
    try:
        with map_zenoh_errors("--connect"):
            session = zenoh.open(conf)
    except Unreachable as exc:
        print(f"pfp status: {exc}", file=sys.stderr)
        return 1
    found = []
    statuses = []
    with session:
        # every reply: two planners sharing an id answer on one key, and Zenoh would keep only one
        every = zenoh.ConsolidationMode.NONE
        for reply in session.get(
            keys.planner_statuses(args.mission), consolidation=every, timeout=args.timeout
        ):
            if reply.ok is not None:
                with contextlib.suppress(InputError):
                    statuses.append(decode_planner_status(reply.ok.payload.to_bytes()))
        for reply in session.get(keys.worlds(args.mission), consolidation=every, timeout=args.timeout):
            if reply.ok is None:
                continue
            try:
                found.append(decode_world_snapshot(reply.ok.payload.to_bytes()))
            except InputError as exc:
                print(f"pfp status: {reply.ok.key_expr}: {exc}", file=sys.stderr)
        if args.json:
            found = [_whole(session, args, snap) for snap in found]
    found.sort(key=lambda s: natural_key(s.planner))
    if args.json:
        print(msgspec.json.encode(found).decode())
    if not found:
        print(
            f"pfp status: no planner of mission {args.mission!r} answered within {args.timeout:g} s",
            file=sys.stderr,
        )
        return 1
    for line in duplicate_warnings(statuses):  # on stderr: a --json reader still gets JSON alone
        print(f"pfp status: {line}", file=sys.stderr)
    if not args.json:
        if statuses:
            print("\n".join(planner_lines(sorted(statuses, key=lambda st: natural_key(st.planner)))))
            print()
        origins = {st.planner: st.origin for st in statuses}
        for i, snap in enumerate(found):
            if i:
                print()
            print("\n".join(snapshot_lines(snap, _coords(args, origins.get(snap.planner)))))
    return 0
