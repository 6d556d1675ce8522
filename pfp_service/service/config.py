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

import json
import tomllib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Literal

import msgspec

from pfp_service.constraints import Finite, Id, NonNegative, Positive
from pfp_service.core import PlannerParams
from pfp_service.core.params import Escape
from pfp_service.errors import InputError, from_validation
from pfp_service.geo import Origin, parse_origin
from pfp_service.scenario import CHOICES

__all__ = [
    "DEFAULT_CONNECT",
    "DEFAULT_LISTEN",
    "ServeConfig",
    "client_zenoh_config",
    "load_config",
    "zenoh_config",
]

DEFAULT_LISTEN = "tcp/127.0.0.1:7447"
DEFAULT_CONNECT = DEFAULT_LISTEN  # where clients look for the embedded router
LogFormat = Literal["human", "json"]
LogLevel = Literal["debug", "info", "warning", "error"]
Mode = Literal["router", "peer", "client"]


class ServeConfig(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """Everything ``pfp serve`` can be told.  See README "Configuration"."""

    mission: Id = "default"
    planner_id: Id = "planner"
    mode: Mode = "router"
    listen: list[str] | None = None  # default for a router with no zenoh_config: DEFAULT_LISTEN
    connect: list[str] = []
    zenoh_config: str | None = None
    multicast: bool = False
    log_format: LogFormat = "human"
    log_level: LogLevel = "info"
    # planner defaults; None means the scale-free rule
    delta: Positive | None = None
    step: Positive | None = None
    tolerance: Positive | None = None
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
    preview_budget_ms: Positive = 500.0
    preview_max_iter: int = 200_000

    def __post_init__(self) -> None:
        if not 0 <= self.lookahead <= 100:
            raise ValueError("lookahead: must be between 0 and 100")
        if self.preview_max_iter < 1:
            raise ValueError("preview_max_iter: must be >= 1")
        if self.bounds is not None:
            (x0, y0), (x1, y1) = self.bounds
            if not (x0 < x1 and y0 < y1):
                raise ValueError("bounds: must be [[xmin, ymin], [xmax, ymax]] with xmin < xmax, ymin < ymax")

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
        try:
            data = tomllib.loads(path.read_text())
        except OSError as exc:
            raise InputError(str(path), f"cannot read: {exc.strerror or exc}") from None
        except tomllib.TOMLDecodeError as exc:
            raise InputError(str(path), f"invalid TOML: {exc}") from None
        layers.append((str(path), data))
    layers.append(("env", _from_env(env)))
    layers.append(("flag", {k: v for k, v in flags.items() if v is not None}))
    return _convert(layers)


def zenoh_config(cfg: ServeConfig) -> Any:
    """The ``zenoh.Config`` for this service: the JSON5 file if any, then our overrides."""
    import zenoh

    if cfg.zenoh_config is not None:
        try:
            conf = zenoh.Config.from_file(cfg.zenoh_config)
        except Exception as exc:  # zenoh raises its own ZError; translate at the edge
            raise InputError("zenoh_config", f"cannot load {cfg.zenoh_config}: {exc}") from None
    else:
        conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(cfg.mode))
    listen = cfg.listen
    if listen is None and cfg.zenoh_config is None and cfg.mode == "router":
        listen = [DEFAULT_LISTEN]
    try:
        if listen is not None:
            conf.insert_json5("listen/endpoints", json.dumps(listen))
        if cfg.connect:
            conf.insert_json5("connect/endpoints", json.dumps(cfg.connect))
        if not cfg.multicast:
            conf.insert_json5("scouting/multicast/enabled", "false")
    except Exception as exc:
        raise InputError("listen/connect", f"rejected by zenoh: {exc}") from None
    return conf


def client_zenoh_config(connect: Sequence[str] | None = None, multicast: bool = False) -> Any:
    """A client-mode ``zenoh.Config`` that connects to ``connect`` (default ``DEFAULT_CONNECT``) only.

    Raises:
        InputError: ``--connect``, when zenoh rejects an endpoint.
    """
    import zenoh

    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    try:
        conf.insert_json5("connect/endpoints", json.dumps(list(connect or [DEFAULT_CONNECT])))
    except Exception as exc:  # zenoh's own error type: translate at the edge
        raise InputError("--connect", f"rejected by zenoh: {exc}") from None
    if not multicast:
        conf.insert_json5("scouting/multicast/enabled", "false")
    return conf
