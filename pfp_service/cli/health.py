"""``pfp health``: exit 0 when a planner of the mission answers its status query, 1 otherwise.

Exit codes: 0 a planner answered; 1 none answered (or no router at the
endpoint), or a twin planner serves the mission (two planners answering the
same units: a WARNING line names them); 2 a bad flag, such as a malformed
``--connect`` endpoint.
``--json`` prints one JSON array of every planner's status, for scripts.
"""

from __future__ import annotations

import argparse
from typing import Any

from pfp_service.cli._common import add_session_args, positive_float, session_config

# the help's example line (cli.build_parser puts it under the parser)
EXAMPLES = {"health": "pfp health --mission exercise1 --timeout 5"}


def register(sub: Any) -> None:
    p = sub.add_parser("health", help="check that a planner answers", description=__doc__)
    add_session_args(p)
    p.add_argument(
        "--timeout", type=positive_float, default=2.0, metavar="S", help="seconds to wait for answers"
    )
    p.add_argument("--json", action="store_true", help="print a JSON array of every planner's status")
    p.set_defaults(func=run)


def _ms(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f} ms"


def status_line(st: Any) -> str:
    """One planner's status for people: rounded figures, units named, no ``None``."""
    return (
        f"{st.planner} ok: mission {st.mission}, up {st.uptime_s:.1f} s, {st.units} units "
        f"({st.units_stale} stale), {st.threats} threats, {st.zones} zones; messages in {st.msgs_in}, out {st.msgs_out}, "
        f"rejected {st.rejected}; latency p50 {_ms(st.latency_p50_ms)}, p99 {_ms(st.latency_p99_ms)}"
    )


def duplicate_warnings(statuses: list[Any]) -> list[str]:
    """A WARNING line per planner that answers the same units as another (``PlannerStatus.twins``).

    Planners sharing an id from several sessions count too, as their replies show them (a planner too old
    to name its twins).
    """
    lines = []
    for st in statuses:
        if st.twins:
            lines.append(
                f"WARNING: twin planner: {', '.join(st.twins)} also answer(s) the units of planner {st.planner} "
                f"(session {st.session[:12]}) on mission {st.mission}; two planners on one mission need "
                "--cluster and each its own --planner-id"
            )
    ids = [st.planner for st in statuses]
    for pid in sorted(set(ids)):
        same = [st for st in statuses if st.planner == pid]
        if len(same) > 1 and not any(st.twins for st in same):
            sessions = ", ".join(st.session[:12] or "?" for st in same)
            lines.append(f"WARNING: twin planner: {len(same)} sessions answer as planner {pid} ({sessions})")
    return lines


def run(args: argparse.Namespace) -> int:
    import sys

    import msgspec
    import zenoh

    from pfp_service.errors import InputError, Unreachable, map_zenoh_errors
    from pfp_service.wire import decode_planner_status, keys

    conf = session_config(args)
    try:
        with map_zenoh_errors("--connect"):
            session = zenoh.open(conf)
    except Unreachable as exc:  # not healthy, and say why
        print(f"pfp health: {exc}", file=sys.stderr)
        return 1
    found = []
    with session:
        every = zenoh.ConsolidationMode.NONE  # two planners sharing an id answer on one key: both count
        for reply in session.get(
            keys.planner_statuses(args.mission), consolidation=every, timeout=args.timeout
        ):
            if reply.ok is None:
                continue
            try:
                found.append(decode_planner_status(reply.ok.payload.to_bytes()))
            except InputError:
                continue
    if args.json:
        print(msgspec.json.encode(found).decode())
    if not found:
        print(
            f"pfp health: no planner of mission {args.mission!r} answered within {args.timeout:g} s",
            file=sys.stderr,
        )
        return 1
    if not args.json:
        for st in found:
            print(status_line(st))
    twins = duplicate_warnings(found)
    for line in twins:
        print(f"pfp health: {line}", file=sys.stderr)
    return 1 if twins else 0
