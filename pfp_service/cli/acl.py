"""``pfp acl TEAM.yaml``: a deny-by-default Zenoh router ACL for one mission, with credentials.

Zenoh's access control is fixed when the router starts and has no templating
by user name, so every unit needs rules of its own: this command writes them
from the team file.  Roles, each a list of grants built from ``wire.keys``
(no topic string is spelled here):

    unit        publish its own state, hold its own token, read its own
                direction, preview its own path, set its own goal (unless
                --no-unit-goals)
    fleet       a simulator playing every unit of the team in one session
                (``pfp fleet``): the unit grants of all of them, reading
                every direction
    planner     read states, goals, threats, zones and unit tokens; publish
                directions and events; serve previews, its status and its
                world; hold its own planner token; see other planners'
                tokens, status and world; share units' missions with them
    reporter    put and delete threats and keep-out zones
    commander   set and cancel any unit's goal, preview any unit
    observer    read everything of the mission, ask any planner's status and
                world (``pfp health``, ``pfp status``)

Everything else is denied: another unit's state, a direction from anyone but
a planner, a planner token or status queryable from anyone else.  A
principal may hold several roles (``--role injector=reporter,commander,observer``).

Writes into ``--out``:

    zenoh-router.json5        router config: usrpwd auth, payload limit, the ACL
    credentials.txt           ``user:password`` lines (kept across runs; 0600)
    clients/NAME.json5        a client config per principal (``pfp serve --zenoh-config``)
    with --tls:
    zenoh-router-mtls.json5   the same ACL with ``cert_common_names`` subjects, mutual TLS
    names.txt                 the common names, for ``docker/gen-certs.py --names-file``
    endpoints.txt             ``NAME ENDPOINT``: a ``--connect`` value carrying that
                              principal's certificate (works with every pfp client)
"""

from __future__ import annotations

import argparse
import json
import os
import secrets
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pfp_service.errors import InputError
from pfp_service.node.access import (  # the rules; this command writes them out
    DEFAULT_PRINCIPALS,
    ROLES,
    Mission,
    client_config,
    principals_for,
    router_config,
    tls_endpoint,
)
from pfp_service.wire import keys


def _pretty(value: Any, pad: str = "") -> str:
    """JSON with one key per line, and each rule, subject or policy on a line of its own."""
    inner = pad + "  "
    if isinstance(value, dict) and value:
        items = [f"{inner}{json.dumps(k)}: {_pretty(v, inner)}" for k, v in value.items()]
        return "{\n" + ",\n".join(items) + "\n" + pad + "}"
    if isinstance(value, list) and any(isinstance(v, dict) for v in value):
        return "[\n" + ",\n".join(inner + json.dumps(v) for v in value) + "\n" + pad + "]"
    return json.dumps(value)


def _dump(obj: dict[str, Any], header: str) -> str:
    return "".join(f"// {line}\n" for line in header.splitlines()) + _pretty(obj) + "\n"


def _read_credentials(path: Path) -> dict[str, str]:
    if not path.exists():
        return {}
    out: dict[str, str] = {}
    for line in path.read_text().splitlines():
        user, sep, pwd = line.partition(":")
        if sep and user and pwd:
            out[user] = pwd
    return out


def _write(path: Path, text: str, private: bool = False) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    if private:  # never world-readable, not even for an instant
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(fd, "w") as f:
            f.write(text)
        os.chmod(path, 0o600)
    else:
        path.write_text(text)


def _parse_roles(specs: Sequence[str] | None, planners: Sequence[str]) -> dict[str, tuple[str, ...]]:
    if not specs:
        return {**{p: ("planner",) for p in planners}, **DEFAULT_PRINCIPALS}
    out: dict[str, tuple[str, ...]] = {}
    for spec in specs:
        name, sep, rest = spec.partition("=")
        rs = tuple(r.strip() for r in rest.split(",") if r.strip())
        if not sep or not name or not rs:
            raise InputError("--role", f"{spec!r}: expected NAME=ROLE[,ROLE...]")
        out[name] = out.get(name, ()) + rs
    return out


# the help's example line (cli.build_parser puts it under the parser)
EXAMPLES = {"acl": "pfp acl examples/demo-team.yaml --out acl"}


def register(sub: Any) -> None:
    p = sub.add_parser("acl", help="write a deny-by-default router ACL and credentials", description=__doc__)
    p.add_argument("team", metavar="TEAM.yaml", help="team file: one unit identity per unit")
    p.add_argument("--out", default="acl", metavar="DIR", help="where to write (default ./acl)")
    p.add_argument("--mission", default=keys.DEFAULT_MISSION)
    p.add_argument(
        "--planner-id",
        action="append",
        metavar="ID",
        help="a planner's id, repeatable for planners sharing the mission (default: planner)",
    )
    p.add_argument(
        "--role",
        action="append",
        metavar="NAME=ROLE[,ROLE]",
        help=f"a principal and its roles ({', '.join(ROLES)}); repeat; default: each planner id as planner, "
        + " ".join(f"{n}={','.join(r)}" for n, r in DEFAULT_PRINCIPALS.items()),
    )
    p.add_argument("--no-unit-goals", action="store_true", help="units may not set their own goal")
    p.add_argument(
        "--listen",
        action="append",
        metavar="ENDPOINT",
        help="router endpoints (default tcp/0.0.0.0:7447, tls/0.0.0.0:7447 with --tls)",
    )
    p.add_argument(
        "--connect-host", default="127.0.0.1:7447", metavar="HOST:PORT", help="what clients connect to"
    )
    p.add_argument(
        "--runtime-dir",
        metavar="DIR",
        help="where these files are when the router and clients run (default: --out, absolute)",
    )
    p.add_argument("--tls", action="store_true", help="also write the mutual-TLS variant")
    p.add_argument("--quiet", action="store_true", help="print nothing on success")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pfp_service.team import load_team

    keys.check_chunk(args.mission, "--mission")
    planners = tuple(dict.fromkeys(args.planner_id or ["planner"]))
    for pid in planners:
        keys.check_chunk(pid, "--planner-id")
    team_file = load_team(args.team)
    team = Mission(
        mission=args.mission,
        planners=planners,
        units=tuple(u.id for u in team_file.units),
        own_goal=not args.no_unit_goals,
    )
    principals = principals_for(team, _parse_roles(args.role, planners))
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise InputError("--out", f"{out} is not a directory")
    runtime = args.runtime_dir or str(out.resolve())
    header = (
        f"Generated by `pfp acl {args.team}` for mission {args.mission!r}: deny by default.\n"
        "Zenoh's ACL is fixed when the router starts: regenerate and restart to change it."
    )
    try:
        creds_path = out / "credentials.txt"
        creds = _read_credentials(creds_path)
        for pr in principals:
            creds.setdefault(pr.name, secrets.token_urlsafe(18))
        names = [pr.name for pr in principals]
        _write(creds_path, "".join(f"{n}:{creds[n]}\n" for n in names), private=True)
        listen = args.listen or ["tcp/0.0.0.0:7447"]
        _write(out / "zenoh-router.json5", _dump(router_config(principals, listen, runtime), header))
        for n in names:
            conf = client_config(n, args.connect_host, runtime, password=creds[n])
            _write(out / "clients" / f"{n}.json5", _dump(conf, f"{n}: {header}"), private=True)
        if args.tls:
            tls_listen = [e.replace("tcp/", "tls/", 1) for e in listen]
            conf = router_config(principals, tls_listen, runtime, tls=True)
            _write(out / "zenoh-router-mtls.json5", _dump(conf, header))
            _write(out / "names.txt", "".join(f"{n}\n" for n in ["router", *names]))
            _write(
                out / "endpoints.txt",
                "".join(f"{n} {tls_endpoint(args.connect_host, n, runtime)}\n" for n in names),
            )
            for n in names:
                conf = client_config(n, args.connect_host, runtime, tls=True)
                _write(out / "clients" / f"{n}-tls.json5", _dump(conf, f"{n}: {header}"))
    except OSError as exc:
        raise InputError(str(out), f"cannot write: {exc.strerror or exc}") from None
    if not args.quiet:
        roles = ", ".join(f"{pr.name} ({'+'.join(pr.roles)})" for pr in principals if pr.roles != ("unit",))
        print(f"{out}: {len(principals)} principals: {roles} and {len(team.units)} units")
        if args.tls:
            print(f"{out}: certificates: python docker/gen-certs.py --out {out} --names-file {out}/names.txt")
    return 0
