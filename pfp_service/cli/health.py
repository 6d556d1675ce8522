"""``pfp health``: exit 0 when a planner of the mission answers its status query, 1 otherwise."""

from __future__ import annotations

import argparse
from typing import Any

from pfp_service.cli._common import positive_float


def register(sub: Any) -> None:
    p = sub.add_parser("health", help="check that a planner answers", description=__doc__)
    p.add_argument(
        "--connect", action="append", metavar="ENDPOINT", help="router to ask (default tcp/127.0.0.1:7447)"
    )
    p.add_argument("--mission", default="default")
    p.add_argument("--timeout", type=positive_float, default=2.0, metavar="S")
    p.add_argument("--json", action="store_true", help="print every planner's status as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import zenoh

    from pfp_service.errors import InputError
    from pfp_service.service.config import DEFAULT_CONNECT, client_zenoh_config
    from pfp_service.wire import decode_planner_status, keys

    keys.check_chunk(args.mission, "--mission")
    conf = client_zenoh_config(args.connect)
    try:
        session = zenoh.open(conf)
    except Exception as exc:  # unreachable router: not healthy, and say why
        print(f"pfp health: cannot reach {', '.join(args.connect or [DEFAULT_CONNECT])}: {exc}")
        return 1
    found = []
    try:
        for reply in session.get(keys.planner_statuses(args.mission), timeout=args.timeout):
            if reply.ok is None:
                continue
            try:
                found.append(decode_planner_status(reply.ok.payload.to_bytes()))
            except InputError:
                continue
    finally:
        session.close()
    if not found:
        print(f"pfp health: no planner of mission {args.mission!r} answered within {args.timeout:g} s")
        return 1
    for st in found:
        if args.json:
            import msgspec

            print(msgspec.json.encode(st).decode())
        else:
            print(
                f"{st.planner} ok: mission {st.mission}, up {st.uptime_s:.1f} s, {st.units} units "
                f"({st.units_stale} stale), {st.threats} threats, in {st.msgs_in}, out {st.msgs_out}, "
                f"rejected {st.rejected}, p50 {st.latency_p50_ms} ms, p99 {st.latency_p99_ms} ms"
            )
    return 0
