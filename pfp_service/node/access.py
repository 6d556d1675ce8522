"""Access control for a mission's router: the grants of each role, built from ``wire.keys``, and the
Zenoh configs that enforce them (a router's ACL and auth, a client's credentials).

Deny by default: a principal (one identity: a unit, a planner, a reporter...) may do only what
its roles grant, each grant naming messages and key expressions.  ``pfp acl`` (``cli/acl.py``)
reads a team file, asks here for the principals and configs, and writes them out; the roles
are described there.  Pure values: nothing here reads or writes a file.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from pfp_service.errors import InputError
from pfp_service.wire import MAX_PAYLOAD_BYTES, keys
from pfp_service.world.kinds import WRITES

__all__ = [
    "DEFAULT_PRINCIPALS",
    "MAX_MESSAGE_BYTES",
    "ROLES",
    "Grant",
    "Mission",
    "Principal",
    "access_control",
    "client_config",
    "principals_for",
    "router_config",
    "tls_endpoint",
]

# Largest Zenoh message a router or planner reassembles (transport/link/rx/max_message_size).
# Twice the wire contract's payload limit leaves room for the key, the encoding and
# attachments; anything bigger is dropped by Zenoh before a callback sees it.  Shared
# memory is turned off with it: between sessions on one host, Zenoh 1.10 hands payloads
# over 3 KiB through shared memory, and those skipped the limit (3 of 3 oversize puts
# delivered in some runs; 0 of 18 with shared memory off).
MAX_MESSAGE_BYTES = 2 * MAX_PAYLOAD_BYTES
INGRESS, EGRESS = "ingress", "egress"


def _tx() -> dict[str, Any]:
    """The transmit queues ``pfp serve`` sets without a Zenoh file (``config.TX_QUEUE_BATCHES``), for every config:
    under Zenoh's 2 batches, directions were dropped whenever a send thread was late (docs/operations.md)."""
    from pfp_service.node.config import tx_queue_sizes

    return {"queue": {"size": tx_queue_sizes()}}


@dataclass(frozen=True)
class Grant:
    """Allow ``messages`` in one ``flow`` (seen from the router) on ``key_exprs``."""

    flow: str
    messages: tuple[str, ...]
    key_exprs: tuple[str, ...]


def _publish(*key_exprs: str, delete: bool = False) -> list[Grant]:
    msgs = ("put", "delete") if delete else ("put",)
    return [Grant(INGRESS, msgs, key_exprs)]


def _acked_write(mission: str, *key_exprs: str) -> list[Grant]:
    """Acknowledged writes of goals, threats and zones (``wire.delivery``): put, delete, ask a planner to take
    them, and watch for planners starting."""
    return [
        *_publish(*key_exprs, delete=True),
        *_query_grants(*key_exprs),
        *_watch_tokens(keys.alive_planners(mission)),
    ]


def _matching(mission: str) -> list[Grant]:
    """Every principal learns which keys of the mission have subscribers and queryables.

    A declared publisher sends nothing while it knows of no matching subscriber
    (write-side filtering), and the planner subscribes with wildcards
    (``unit/*/state``): a unit allowed to learn only of subscriptions to its
    own key would never learn of the planner's and its states would never leave it.
    """
    return [Grant(EGRESS, ("declare_subscriber", "declare_queryable"), (keys.mission_all(mission),))]


def _subscribe(*key_exprs: str) -> list[Grant]:
    return [
        Grant(INGRESS, ("declare_subscriber",), key_exprs),
        Grant(EGRESS, ("put", "delete"), key_exprs),
    ]


def _query_grants(*key_exprs: str) -> list[Grant]:
    return [Grant(INGRESS, ("query",), key_exprs), Grant(EGRESS, ("reply",), key_exprs)]


def _token(*key_exprs: str) -> list[Grant]:
    return [Grant(INGRESS, ("liveliness_token",), key_exprs)]


def _watch_tokens(*key_exprs: str) -> list[Grant]:
    return [
        Grant(INGRESS, ("declare_liveliness_subscriber", "liveliness_query"), key_exprs),
        Grant(EGRESS, ("liveliness_token", "reply"), key_exprs),
    ]


def _written_by(role: str, mission: str) -> tuple[str, ...]:
    """The write kinds' keys (``world.kinds.WRITES``) a role may put and delete, as wildcards."""
    return tuple(k.wildcard(mission) for k in WRITES if role in k.writers)


def unit_grants(mission: str, unit: str, own_goal: bool = True) -> list[Grant]:
    """What unit ``unit`` may do: its own state, token, direction, preview (and goal)."""
    out = [
        *_publish(keys.unit_state(mission, unit), keys.shard_state(mission, unit)),
        *_token(keys.alive_unit(mission, unit)),
        *_subscribe(keys.unit_direction(mission, unit)),
        *_query_grants(keys.preview(mission, unit)),
    ]
    if own_goal:  # the write kinds a unit may write on its own key (its goal)
        out += _acked_write(mission, *(k.key_of(mission, unit) for k in WRITES if k.own_unit))
    return out


def fleet_grants(mission: str, units: Sequence[str], own_goal: bool = True) -> list[Grant]:
    """A simulator that plays every unit of ``units`` and reads every direction (``pfp fleet``)."""
    out: list[Grant] = []
    for u in units:
        out += unit_grants(mission, u, own_goal)
    return out + _subscribe(keys.unit_directions(mission))


def planner_grants(mission: str, planner: str) -> list[Grant]:
    own = (keys.planner_status(mission, planner), keys.world(mission, planner))
    every = (keys.planner_statuses(mission), keys.worlds(mission))
    writes = tuple(k.wildcard(mission) for k in WRITES)  # every write kind: read and acknowledged
    previews = (keys.previews(mission), keys.team_previews(mission))  # a unit's, a team's
    return [
        *_subscribe(keys.unit_states(mission), keys.sharded_states(mission), *writes),
        *_watch_tokens(keys.alive_units(mission), keys.alive_planners(mission)),
        *_publish(keys.unit_directions(mission), keys.events(mission)),
        # scale-out (`pfp serve --cluster`): planners share each unit's fixed mission
        *_publish(keys.unit_missions(mission)),
        *_subscribe(keys.unit_missions(mission)),
        # its own status and world queryables; replies also on the wildcards that
        # `pfp health` and `pfp status` ask with
        # ... and the goal, threat and zone queryables that acknowledge writes (wire.delivery)
        Grant(INGRESS, ("declare_queryable",), (*previews, *own, *writes)),
        Grant(INGRESS, ("reply",), (*previews, *every, *writes)),
        Grant(EGRESS, ("query",), (*previews, *every, *writes)),
        *_token(keys.alive_planner(mission, planner)),
        # other planners' status and world: conflict detection, `pfp health` with the planner's identity
        *_query_grants(*every),
    ]


def reporter_grants(mission: str) -> list[Grant]:
    return _acked_write(mission, *_written_by("reporter", mission))


def commander_grants(mission: str) -> list[Grant]:
    return [
        *_acked_write(mission, *_written_by("commander", mission)),
        *_query_grants(keys.previews(mission), keys.team_previews(mission)),
    ]


def observer_grants(mission: str) -> list[Grant]:
    return [
        *_subscribe(keys.mission_all(mission)),
        *_watch_tokens(keys.alive_units(mission), keys.alive_planners(mission)),
        *_query_grants(keys.planner_statuses(mission), keys.worlds(mission)),
    ]


@dataclass(frozen=True)
class Mission:
    """What a role needs to know: the mission, its planners' ids, the team's units and the goal policy."""

    mission: str
    planners: tuple[str, ...]
    units: tuple[str, ...]
    own_goal: bool = True


def _planner_role(t: Mission, name: str) -> list[Grant]:
    # a principal named after a planner id holds that planner's token and queryables
    return planner_grants(t.mission, name if name in t.planners else t.planners[0])


# The mission-wide roles a principal (by name) can be given with --role; ``unit`` is per team unit.
ROLES: dict[str, Callable[[Mission, str], list[Grant]]] = {
    "planner": _planner_role,
    "fleet": lambda t, _name: fleet_grants(t.mission, t.units, t.own_goal),
    "reporter": lambda t, _name: reporter_grants(t.mission),
    "commander": lambda t, _name: commander_grants(t.mission),
    "observer": lambda t, _name: observer_grants(t.mission),
}

# Who gets an identity when --role is not given: each --planner-id (role planner), then one
# per role, plus what `pfp inject` and `pfp map` need.
DEFAULT_PRINCIPALS: dict[str, tuple[str, ...]] = {
    "fleet": ("fleet",),
    "injector": ("reporter", "commander", "observer"),
    "map": ("reporter", "commander", "observer"),  # pfp map shows everything, edits threats, zones, goals
    "reporter": ("reporter",),
    "commander": ("commander",),
    "observer": ("observer",),
}
UNIT_PREFIX = "unit-"


@dataclass(frozen=True)
class Principal:
    """One identity (a user name, or a certificate's common name) and what it may do."""

    name: str
    roles: tuple[str, ...]
    grants: tuple[Grant, ...]


def principals_for(team: Mission, roles: dict[str, tuple[str, ...]]) -> list[Principal]:
    """Every principal: ``roles`` (name -> role names) then ``unit-<id>`` for each unit.

    Raises:
        InputError: an unknown role, or a name clash with a unit's principal.
    """
    out: list[Principal] = []
    for name, rs in roles.items():
        keys.check_chunk(name, "--role")
        if name.startswith(UNIT_PREFIX):
            raise InputError("--role", f"{name!r}: names starting with {UNIT_PREFIX!r} are the units'")
        grants: list[Grant] = []
        for r in rs:
            if r not in ROLES:
                raise InputError("--role", f"{name}={r}: unknown role (expected one of: {', '.join(ROLES)})")
            grants += ROLES[r](team, name)
        out.append(Principal(name, tuple(rs), tuple(grants + _matching(team.mission))))
    for u in team.units:
        grants = unit_grants(team.mission, u, team.own_goal) + _matching(team.mission)
        out.append(Principal(UNIT_PREFIX + u, ("unit",), tuple(grants)))
    return out


def access_control(principals: Iterable[Principal], tls: bool = False) -> dict[str, Any]:
    """The router's ``access_control`` section: deny by default, one subject and policy per principal."""
    rules: list[dict[str, Any]] = []
    subjects: list[dict[str, Any]] = []
    policies: list[dict[str, Any]] = []
    for p in principals:
        ids = []
        for i, g in enumerate(p.grants):
            rid = f"{p.name}-{i}"
            ids.append(rid)
            rules.append(
                {
                    "id": rid,
                    "permission": "allow",
                    "flows": [g.flow],
                    "messages": list(g.messages),
                    "key_exprs": list(g.key_exprs),
                }
            )
        subjects.append({"id": p.name, ("cert_common_names" if tls else "usernames"): [p.name]})
        policies.append({"id": p.name, "rules": ids, "subjects": [p.name]})
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    }


def router_config(
    principals: Sequence[Principal], listen: Sequence[str], runtime_dir: str, tls: bool = False
) -> dict[str, Any]:
    """A whole router config (zenohd or a Python session in router mode).

    Args:
        principals: from ``principals_for``.
        listen: endpoints, ``tcp/...`` (``tls/...`` with ``tls``).
        runtime_dir: where credentials.txt (or the PEM files) are when the router runs.
        tls: mutual TLS with ``cert_common_names`` subjects instead of user/password.
    """
    link: dict[str, Any] = {"rx": {"max_message_size": MAX_MESSAGE_BYTES}, "tx": _tx()}
    transport: dict[str, Any] = {"link": link, "shared_memory": {"enabled": False}}
    if tls:
        link["tls"] = {
            "root_ca_certificate": f"{runtime_dir}/ca.pem",
            "listen_private_key": f"{runtime_dir}/router-key.pem",
            "listen_certificate": f"{runtime_dir}/router.pem",
            "enable_mtls": True,
        }
    else:
        transport["auth"] = {"usrpwd": {"dictionary_file": f"{runtime_dir}/credentials.txt"}}
    return {
        "mode": "router",
        "listen": {"endpoints": list(listen)},
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
        "transport": transport,
        "access_control": access_control(principals, tls),
    }


def tls_endpoint(host_port: str, name: str, runtime_dir: str) -> str:
    """A ``--connect`` value that carries ``name``'s certificate: ``tls/HOST:PORT#...``."""
    return (
        f"tls/{host_port}#root_ca_certificate_file={runtime_dir}/ca.pem;"
        f"connect_private_key_file={runtime_dir}/{name}-key.pem;"
        f"connect_certificate_file={runtime_dir}/{name}.pem;enable_mtls=true"
    )


def client_config(
    name: str, connect: str, runtime_dir: str, password: str | None = None, tls: bool = False
) -> dict[str, Any]:
    """A client config for one principal: ``password`` for usrpwd, or its certificate with ``tls``."""
    transport: dict[str, Any] = {
        "link": {"rx": {"max_message_size": MAX_MESSAGE_BYTES}, "tx": _tx()},
        "shared_memory": {"enabled": False},
    }
    if tls:
        transport["link"]["tls"] = {
            "root_ca_certificate": f"{runtime_dir}/ca.pem",
            "connect_private_key": f"{runtime_dir}/{name}-key.pem",
            "connect_certificate": f"{runtime_dir}/{name}.pem",
            "enable_mtls": True,
        }
        endpoint = f"tls/{connect}"
    else:
        transport["auth"] = {"usrpwd": {"user": name, "password": password}}
        endpoint = f"tcp/{connect}"
    return {
        "mode": "client",
        "connect": {"endpoints": [endpoint]},
        "scouting": {"multicast": {"enabled": False}},
        "transport": transport,
    }
