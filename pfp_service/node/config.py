"""Service configuration: one frozen object, merged once at the edge.

Precedence, lowest to highest: built-in defaults < TOML file (``--config``)
< ``PFP_*`` environment variables < command-line flags.  Every key has the
same name in all three (``unit_stale_s`` is ``PFP_UNIT_STALE_S`` and
``--unit-stale-s``); lists in the environment are comma-separated.  Zenoh's
own settings may come from a JSON5 file (``zenoh_config``); ``mode``,
``listen`` and ``connect`` given here override that file.

Nothing deeper than this module reads the environment.
"""

from __future__ import annotations

import dataclasses
import json
import tomllib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal

import msgspec
from msgspec import Meta

from pfp_service.bounds import check_depth, scan_toml
from pfp_service.constraints import Delta, Finite, Id, NonNegative, Positive, Step, Tolerance
from pfp_service.core import PlannerParams
from pfp_service.core.mobility import MobilityClass
from pfp_service.core.params import Escape
from pfp_service.errors import InputError, from_validation, map_zenoh_errors
from pfp_service.files import read_text
from pfp_service.geo import Origin, localise_document, parse_origin
from pfp_service.scenario import CHOICES

if TYPE_CHECKING:
    from pfp_service.world.events import WorldSettings
    from pfp_service.world.separations import DispersionSettings

__all__ = [
    "CONNECT_RETRY",
    "DEFAULT_CONNECT",
    "DEFAULT_ENDPOINT",
    "DEFAULT_LISTEN",
    "ServeConfig",
    "build_zenoh_config",
    "client_zenoh_config",
    "load_config",
    "zenoh_config",
]

# The one place the default endpoint is written: the embedded router listens here, clients look here.
DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
DEFAULT_LISTEN = DEFAULT_ENDPOINT
DEFAULT_CONNECT = DEFAULT_ENDPOINT
# How often a session retries its connect endpoints while nothing answers there.  Zenoh's default
# backoff grows to several seconds: a planner started before its router answered 8.1 s after the
# router came up.  Capped at 1 s, it answers within about a second (the whole object is inserted:
# Zenoh refuses the dotted keys one by one).
CONNECT_RETRY = {"period_init_ms": 100, "period_max_ms": 1000, "period_increase_factor": 1.5}
# The planner's transmit queue per link and priority, in batches, without a zenoh_config file (Zenoh's default
# is 2): directions and the rest go out with DROP and a short wait, so a queue too short drops them whenever
# Zenoh's send thread is late; a batch is allocated only when a link falls behind (figures:
# docs/operations.md, "Figures behind the code's choices").
TX_QUEUE_BATCHES = {"interactive_high": 16, "data": 16}
# A router-mode session binds its listeners, then spends Zenoh's scouting delay (500 ms by default) in
# open() before it returns: clients connected and put meanwhile, and every goal put in that window was
# lost, the planner having no subscriber yet (issue 34: a plain put 1.2 s after `pfp serve` launched).
# With multicast scouting off there is nothing to wait for: open() returns as the port opens, and the
# planner subscribes just after (docs/operations.md, "Figures behind the code's choices"). A file's own
# scouting/delay, and a planner that scouts by multicast, keep theirs.
ROUTER_SCOUTING_DELAY_MS = 0
LogFormat = Literal["human", "json"]
LogLevel = Literal["debug", "info", "warning", "error"]
CoordsStyle = Literal["latlon", "metres", "mgrs"]  # pfp_service.coords.STYLES
Mode = Literal["router", "peer", "client"]


class ServeConfig(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """Everything ``pfp serve`` can be told.  See docs/operations.md, "Configuration"."""

    mission: Id = "default"
    planner_id: Id = "planner"
    mode: Mode = "router"
    listen: list[str] | None = None  # default for a router with no zenoh_config: DEFAULT_LISTEN
    connect: list[str] = []
    zenoh_config: str | None = None
    multicast: bool = False
    log_format: LogFormat = "human"
    log_level: LogLevel = "info"
    coords: CoordsStyle | None = None  # the human log's positions; None: latlon with an origin, else metres
    # planner defaults; None means the scale-free rule
    delta: Delta | None = None
    step: Step | None = None
    tolerance: Tolerance | None = None
    intensity: Literal["peak", "density"] = "peak"
    escape: Escape = "auto"
    # the live world
    bounds: tuple[tuple[Finite, Finite], tuple[Finite, Finite]] | None = None
    origin: Origin | None = None  # the mission origin; lat/lon positions become metres from it
    threat_ttl_s: Positive | None = None
    unit_stale_s: Positive = 10.0
    liveliness_debounce_s: NonNegative = 2.0
    lookahead: int = 5
    tick_s: Positive = 0.05
    loop_trace: str | None = None  # a file: the planning loop's time, a JSON line a second (LoopTrace)
    preview_budget_ms: Positive = 500.0
    team_preview_budget_ms: Positive = 5000.0  # a team's replay: every member, a world's apply per step
    preview_max_iter: int = 200_000
    preview_workers: Annotated[int, Meta(ge=1, le=64)] = 2
    preview_queue: Annotated[int, Meta(ge=1, le=100_000)] = 256
    preview_wait_ms: Positive = 2000.0  # a preview that cannot start within this is answered busy at once
    # deliberation (look-ahead, escape searches) off the planning loop
    deliberation_workers: Annotated[int, Meta(ge=1, le=64)] = 1
    deliberation_budget_s: Positive = 5.0
    # bounded memory under overload
    unit_forget_s: Positive | None = 600.0
    max_units: Annotated[int, Meta(ge=1, le=10_000_000)] = 100_000
    max_threats: Annotated[int, Meta(ge=1, le=1_000_000)] = 10_000
    zones: str | None = (
        None  # a GeoJSON file of keep-out zones, put when the planner starts (geojson.load_zones)
    )
    # durable state: "auto" is a per-mission directory under the user's state directory
    # (resolved by load_config), "none" turns it off
    state_dir: str = "auto"
    # scale-out: several planners share the mission, each guiding the units rendezvous hashing gives it
    cluster: bool = False
    # a DEM planned over (terrain.live): threats masked by line of sight, slopes past the class a barrier
    terrain: str | None = None
    terrain_unit: Literal["foot", "wheeled", "tracked"] = "foot"  # the mobility class planned for
    sight_wait_s: Positive = 0.25  # a threat over terrain held this long for its window, then in force blind
    # dispersion between friendly units (docs/operations.md, "Dispersion"): off unless turned on
    dispersion: bool = False
    separation_m: dict[MobilityClass, Positive] = {}  # a class's separation, over the defaults
    unit_class: dict[Id, MobilityClass] = {}  # each unit's mobility class, where not default_class
    default_class: MobilityClass = "wheeled"
    manned_first: bool = True  # right of way: manned before unmanned, then by id (off: by id alone)
    deadlock_s: Positive = 6.0  # a unit held this long is in a deadlock, and backs off as long

    def __post_init__(self) -> None:
        if not 0 <= self.lookahead <= 100:
            raise ValueError("lookahead: must be between 0 and 100")
        if self.preview_max_iter < 1:
            raise ValueError("preview_max_iter: must be >= 1")
        if self.bounds is not None:
            (x0, y0), (x1, y1) = self.bounds
            if not (x0 < x1 and y0 < y1):
                raise ValueError("bounds: must be [[xmin, ymin], [xmax, ymax]] with xmin < xmax, ymin < ymax")

    def world_settings(self) -> WorldSettings:
        """What the live world needs of this configuration (deliberation is always deferred in the daemon)."""
        from pfp_service.world.events import WorldSettings

        settings = WorldSettings(
            planner=self.planner_params(),
            threat_ttl_s=self.threat_ttl_s,
            unit_stale_s=self.unit_stale_s,
            liveliness_debounce_s=self.liveliness_debounce_s,
            lookahead=self.lookahead,
            bounds=self.bounds_tuple(),
            mission=self.mission,
            planner_id=self.planner_id,
            deliberation="deferred",
            deliberation_budget_s=self.deliberation_budget_s,
            unit_forget_s=self.unit_forget_s,
            max_units=self.max_units,
            max_threats=self.max_threats,
            origin=self.origin,
            cluster=self.cluster,
            dispersion=self.dispersion_settings(),
            sight_wait_s=self.sight_wait_s,
        )
        if self.terrain is not None:  # loaded once per process (terrain.live.load), then shared
            from pfp_service.terrain.live import load

            ground = load(self.terrain, self.origin, self.bounds_tuple(), self.terrain_unit)
            settings = dataclasses.replace(
                settings, terrain=ground, bounds=ground.bounds, origin=ground.origin
            )
        return settings

    def dispersion_settings(self) -> DispersionSettings:
        """The world's dispersion settings: the class defaults with this file's overrides."""
        from pfp_service.world.separations import SEPARATION_M, DispersionSettings

        separation: dict[str, float] = dict(SEPARATION_M)
        separation.update((str(k), v) for k, v in self.separation_m.items())
        return DispersionSettings(
            enabled=self.dispersion,
            separation_m=separation,
            default_class=self.default_class,
            classes=dict(self.unit_class),
            manned_first=self.manned_first,
            deadlock_s=self.deadlock_s,
            backoff_s=self.deadlock_s,
        )

    def bounds_tuple(self) -> tuple[tuple[float, float], tuple[float, float]] | None:
        if self.bounds is None:
            return None
        (x0, y0), (x1, y1) = self.bounds
        return (x0, y0), (x1, y1)

    def planner_params(self) -> PlannerParams:
        return PlannerParams(
            delta=self.delta,
            step=self.step,
            tolerance=self.tolerance,
            intensity=self.intensity,
            escape=self.escape,
        )


_FIELDS = set(ServeConfig.__struct_fields__)
_LISTS = {"listen", "connect"}


def _from_env(env: Mapping[str, str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for name in _FIELDS:
        raw = env.get("PFP_" + name.upper())
        if raw is None:
            continue
        if name in _LISTS:
            out[name] = [s.strip() for s in raw.split(",") if s.strip()]
        elif name == "origin":
            try:
                out[name] = msgspec.to_builtins(parse_origin(raw))
            except InputError as exc:
                raise InputError("PFP_ORIGIN", exc.reason) from None
        elif name == "bounds":
            try:
                out[name] = json.loads(raw)
            except json.JSONDecodeError:
                raise InputError("PFP_BOUNDS", "expected JSON like [[0, 0], [100, 100]]") from None
        else:
            out[name] = raw
    return out


def _convert(layers: list[tuple[str, dict[str, Any]]]) -> ServeConfig:
    merged: dict[str, Any] = {}
    origin: dict[str, str] = {}
    for where, layer in layers:
        for k, v in layer.items():
            merged[k] = v
            origin[k] = where
    try:
        merged = localise_document(merged)  # bounds may be {lat, lon} corners once there is an origin
    except InputError as exc:
        where = origin.get(exc.path.split(".")[0].split("[")[0], "")
        raise InputError(f"{where}: {exc.path}" if where else exc.path, exc.reason) from None
    try:
        return msgspec.convert(merged, ServeConfig, strict=False)
    except msgspec.ValidationError as exc:
        err = from_validation(exc, CHOICES)
        top = err.path.split(".")[0].split("[")[0]
        where = origin.get(top, "")
        if where.startswith("env"):
            raise InputError("PFP_" + top.upper(), err.reason) from None
        prefix = f"{where}: " if where and not where.startswith("flag") else ""
        raise InputError(
            prefix + (err.path if not where.startswith("flag") else "--" + err.path.replace("_", "-")),
            err.reason,
        ) from None


def load_config(file: str | Path | None, env: Mapping[str, str], flags: Mapping[str, Any]) -> ServeConfig:
    """Merge defaults, a TOML file, ``PFP_*`` variables and flags (``None`` flags are unset).

    Raises:
        InputError: naming the file key, variable or flag and why.
    """
    layers: list[tuple[str, dict[str, Any]]] = []
    if file is not None:
        path = Path(file)
        text = read_text(path)
        scan_toml(text, str(path))  # nesting past the bound would end tomllib in a RecursionError
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise InputError(str(path), f"invalid TOML: {exc}") from None
        check_depth(data, str(path))  # dotted keys nest without brackets
        layers.append((str(path), data))
    layers.append(("env", _from_env(env)))
    layers.append(("flag", {k: v for k, v in flags.items() if v is not None}))
    cfg = _convert(layers)
    if cfg.state_dir == "auto":
        cfg = msgspec.structs.replace(cfg, state_dir=str(default_state_dir(env, cfg.mission)))
    return cfg


def default_state_dir(env: Mapping[str, str], mission: str) -> Path:
    """``$XDG_STATE_HOME/pfp/{mission}``, or ``~/.local/state/pfp/{mission}``."""
    base = env.get("XDG_STATE_HOME") or str(Path(env.get("HOME") or Path.home()) / ".local" / "state")
    return Path(base) / "pfp" / mission


def build_zenoh_config(
    *,
    mode: str,
    listen: Sequence[str] | None = None,
    connect: Sequence[str] | None = None,
    multicast: bool = False,
    file: str | None = None,
    file_setting: str = "zenoh_config",
) -> Any:
    """A ``zenoh.Config``: the JSON5 ``file`` if any, then ``mode``, ``listen`` and ``connect`` over it.

    Args:
        file_setting: what a bad ``file`` is reported as (the setting or flag that named it).

    Raises:
        ZenohError: naming the file, ``--listen`` or ``--connect``, in Zenoh's words made readable.
    """
    import zenoh

    if file is not None:
        with map_zenoh_errors(file_setting, about=file):
            conf = zenoh.Config.from_file(file)
    else:
        conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    if listen is not None:
        with map_zenoh_errors("--listen"):
            conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
    if connect:
        with map_zenoh_errors("--connect"):
            conf.insert_json5("connect/endpoints", json.dumps(list(connect)))
    if not multicast:
        conf.insert_json5("scouting/multicast/enabled", "false")
    if conf.get_json("connect/retry") == "null":  # a file's own retry settings win
        conf.insert_json5("connect/retry", json.dumps(CONNECT_RETRY))
    return conf


def zenoh_config(cfg: ServeConfig) -> Any:
    """The ``zenoh.Config`` for this service: the JSON5 file if any, then our overrides; without a file, also
    deeper transmit queues (``TX_QUEUE_BATCHES``)."""
    listen = cfg.listen
    if listen is None and cfg.zenoh_config is None and cfg.mode == "router":
        listen = [DEFAULT_LISTEN]
    conf = build_zenoh_config(
        mode=cfg.mode, listen=listen, connect=cfg.connect, multicast=cfg.multicast, file=cfg.zenoh_config
    )
    if cfg.zenoh_config is None:  # a file's own transport settings win
        conf.insert_json5("transport/link/tx/queue/size", json.dumps(_queue_sizes(conf)))
    if cfg.mode == "router" and not cfg.multicast and conf.get_json("scouting/delay") == "null":
        conf.insert_json5("scouting/delay", json.dumps(ROUTER_SCOUTING_DELAY_MS))
    return conf


def _queue_sizes(conf: Any) -> dict[str, int]:
    """Zenoh's transmit queue sizes with ``TX_QUEUE_BATCHES`` over them (the whole object: see CONNECT_RETRY)."""
    sizes = dict(json.loads(conf.get_json("transport/link/tx/queue/size")))
    return {**sizes, **TX_QUEUE_BATCHES}


def tx_queue_sizes() -> dict[str, int]:
    """``transport/link/tx/queue/size`` as ``pfp serve`` sets it without a file: what ``pfp acl`` writes too."""
    import zenoh

    return _queue_sizes(zenoh.Config())


def client_zenoh_config(
    connect: Sequence[str] | None = None,
    multicast: bool = False,
    mode: str = "client",
    listen: Sequence[str] | None = None,
    file: str | None = None,
) -> Any:
    """A ``zenoh.Config`` for a client program: ``mode`` (client by default) joining ``connect``.

    Args:
        connect: endpoints to join; else the file's ``connect/endpoints``; else ``DEFAULT_CONNECT``.
        file: a Zenoh JSON5 file to start from (``--zenoh-config``), e.g. one ``pfp acl`` wrote with
            the client's user and password; ``mode``, ``listen`` and ``connect`` override it.

    Raises:
        ZenohError: ``--zenoh-config`` (unreadable or invalid file), ``--connect`` or ``--listen``.
    """
    conf = build_zenoh_config(
        mode=mode,
        listen=listen,
        connect=connect,
        multicast=multicast,
        file=file,
        file_setting="--zenoh-config",
    )
    if conf.get_json("connect/endpoints") in ("[]", "null"):  # neither a flag nor the file says where
        conf.insert_json5("connect/endpoints", json.dumps([DEFAULT_CONNECT]))
    return conf
