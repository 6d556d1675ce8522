"""Scenario files: YAML or JSON, decoded into typed, validated structs.

A scenario names a start, a goal, optional mission bounds, planner settings
and threats (each optionally popping up at a step).  With an ``origin``
(``{lat, lon, alt}``), every position (start, goal, bounds corners, threat
positions) may be ``{lat, lon}`` instead of ``[x, y]`` metres; it is turned
into metres on decoding (``geo.localise``), so the rest never sees a degree.
Keep-out ``zones:`` are the wire's zone form with an ``id`` (``ZoneSpec``):
a ``polygon`` (closed rings, the outer first, vertices ``[x, y]`` or
``{lat, lon}``) or a ``circle`` (``centre``, ``radius_m``).  ``load_scenario`` is the
only function here that touches the file system; ``decode_scenario`` works on
bytes, and ``Scenario.to_plan_args`` hands the core what it needs.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Collection, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Literal

import msgspec
import yaml
from msgspec import Meta

from pfp_service import bounds, yamlio
from pfp_service.constraints import (
    Delta,
    Finite,
    Id,
    Iterations,
    Point,
    Sigma,
    Skew,
    Step,
    StepIndex,
    Tolerance,
    Weight,
    check_spreads,
)
from pfp_service.core.mobility import CLASSES, Mobility
from pfp_service.core.params import ESCAPES, Escape, PlannerParams, reach
from pfp_service.errors import InputError, from_validation
from pfp_service.files import read_text
from pfp_service.geo import Origin, localise_document
from pfp_service.wire.messages import TeamUpdate, ZoneUpdate, localise_zone, team_problems
from pfp_service.wire.messages.structs import DEFAULT_SHAPE, ShapeName, ShapeParams

if TYPE_CHECKING:
    # Imported where used: a scenario is read (and a hostile one refused) without compiling the core.
    from pfp_service.core.plan import Scheduled
    from pfp_service.core.threat import Threat
    from pfp_service.core.zones import ZoneSet

__all__ = [
    "CHOICES",
    "PlannerSpec",
    "Scenario",
    "TeamSpec",
    "ThreatSpec",
    "UnitSpec",
    "ZoneSpec",
    "check_teams",
    "decode_scenario",
    "load_scenario",
]

Matrix = tuple[tuple[Finite, Finite], tuple[Finite, Finite]]
CHOICES: dict[str, tuple[str, ...]] = {
    "intensity": ("peak", "density"),
    "escape": ESCAPES,
    "class": tuple(CLASSES),
}
# an eye or a unit's height above its ground, metres: a mast, not an aircraft
Height = Annotated[float, Meta(ge=0.0, le=1000.0)]
SlopeLimit = Annotated[float, Meta(gt=0.0, lt=90.0)]
Speed = Annotated[float, Meta(gt=0.0, le=1000.0)]


class ThreatSpec(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """One threat, in user-facing form or raw skew-normal form.

    User form: ``position, facing_deg, sigma_range, sigma_lateral, skew, weight``.
    Raw form: ``position`` (xi), ``omega`` (2x2 SPD) and ``alpha`` instead of the
    facing, sigmas and skew.  Another shape (``core.shapes``): ``shape`` and its
    ``params``, as on the wire.
    """

    id: Id | None = None
    position: Point
    shape: ShapeName = DEFAULT_SHAPE
    params: ShapeParams | None = None
    facing_deg: Finite = 0.0
    sigma_range: Sigma | None = None
    sigma_lateral: Sigma | None = None
    skew: Skew = 0.0
    weight: Weight = 1.0
    appear_step: StepIndex = 0
    omega: Matrix | None = None
    alpha: Point | None = None
    observer_height_m: Height = 2.0

    def __post_init__(self) -> None:
        if self.shape != DEFAULT_SHAPE:
            if self.omega is not None or self.sigma_range is not None or self.sigma_lateral is not None:
                raise ValueError(f"shape: a {self.shape} threat takes params, not omega or sigmas")
            from pfp_service.core import shapes

            shapes.check_params(shapes.get(self.shape), self.params or {})
            return
        if self.params:
            raise ValueError("params: the skew_normal shape takes its fields at the top level")
        if self.omega is None:
            if self.sigma_range is None:
                raise ValueError("sigma_range: is required (or give the raw form omega and alpha)")
            if self.sigma_lateral is None:
                raise ValueError("sigma_lateral: is required (or give the raw form omega and alpha)")
            if self.alpha is not None:
                raise ValueError("alpha: goes with omega (the raw form), not with sigma_range")
            check_spreads(self.sigma_range, self.sigma_lateral)
            return
        if self.sigma_range is not None or self.sigma_lateral is not None:
            raise ValueError("omega: give either omega or sigma_range/sigma_lateral, not both")
        (a, b), (c, d) = self.omega
        if b != c:
            raise ValueError("omega: must be symmetric")
        det = a * d - b * c  # as the field will compute it: it may underflow to 0 or overflow
        if not (a > 0 and d > 0 and math.isfinite(det) and det > 0):
            raise ValueError("omega: must be positive definite")
        try:
            self.to_threat("")
        except ValueError:
            raise ValueError("omega: must be positive definite and invertible in floating point") from None

    def to_threat(self, default_id: str) -> Threat:
        from pfp_service.core.threat import Threat

        tid = self.id or default_id
        if self.shape != DEFAULT_SHAPE:
            from pfp_service.core import shapes

            shape = shapes.get(self.shape)
            params = shapes.check_params(shape, self.params or {})
            t = shape.threat((self.position[0], self.position[1]), params, self.weight, tid)
            return dataclasses.replace(t, observer_height_m=self.observer_height_m)
        if self.omega is None:
            assert self.sigma_range is not None and self.sigma_lateral is not None
            return Threat.from_facing(
                self.position,
                self.facing_deg,
                self.sigma_range,
                self.sigma_lateral,
                self.skew,
                self.weight,
                tid,
                self.observer_height_m,
            )
        alpha = self.alpha if self.alpha is not None else (0.0, 0.0)
        return Threat(
            xi=(self.position[0], self.position[1]),
            omega=((self.omega[0][0], self.omega[0][1]), (self.omega[1][0], self.omega[1][1])),
            alpha=(alpha[0], alpha[1]),
            weight=self.weight,
            id=tid,
            observer_height_m=self.observer_height_m,
        )


class PlannerSpec(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """Planner settings; anything left out is derived by the scale-free rule."""

    delta: Delta | None = None
    step: Step | None = None
    max_iter: Iterations | None = None
    tolerance: Tolerance | None = None
    intensity: Literal["peak", "density"] = "peak"
    escape: Escape = "auto"
    seed: int = 0

    def to_params(self) -> PlannerParams:
        return PlannerParams(
            delta=self.delta,
            step=self.step,
            max_iter=self.max_iter,
            tolerance=self.tolerance,
            intensity=self.intensity,
            escape=self.escape,
            seed=self.seed,
        )


class UnitSpec(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """The unit's mobility class (``core.mobility.CLASSES``) and any of its fields overridden."""

    kind: Literal["foot", "wheeled", "tracked"] = msgspec.field(default="foot", name="class")
    max_slope_deg: SlopeLimit | None = None
    height_m: Height | None = None
    speed_mps: Speed | None = None

    def mobility(self) -> Mobility:
        return CLASSES[self.kind].merged(self.max_slope_deg, self.height_m, self.speed_mps)


class ZoneSpec(ZoneUpdate, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """A keep-out zone in a file: the wire's ``ZoneUpdate`` with its ``id`` (default ``zN``)."""

    id: Id | None = None


class TeamSpec(TeamUpdate, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """A team in a file: the wire's ``TeamUpdate`` with its ``id``."""

    id: Id


def check_teams(teams: Sequence[TeamSpec], known: Collection[str] | None) -> None:
    """A file's ``teams:`` as the planner would take them: distinct ids, and no ``team_problems``.

    Raises:
        ValueError: ``teams[i].field: reason`` for the first team refused.
    """
    index: dict[str, int] = {}
    for i, t in enumerate(teams):
        if t.id in index:
            raise ValueError(f"teams[{i}].id: duplicate id {t.id!r}")
        index[t.id] = i
    for p in team_problems({t.id: t for t in teams}, known):
        raise ValueError(f"teams[{index[p.team]}].{p.error.path}: {p.error.reason}")


class Scenario(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """A whole planning problem, as written in a scenario file."""

    name: str = "scenario"
    origin: Origin | None = None
    start: Point
    goal: Point
    bounds: tuple[Point, Point] | None = None
    planner: PlannerSpec = PlannerSpec()
    threats: list[ThreatSpec] = []
    zones: list[ZoneSpec] = []
    terrain: str | None = None  # a DEM's path, relative to the scenario file
    unit: UnitSpec = UnitSpec()
    teams: Annotated[
        list[TeamSpec], Meta(max_length=1_000)
    ] = []  # checked as a team file's are; one unit plans alone

    def __post_init__(self) -> None:
        if self.bounds is not None:
            (x0, y0), (x1, y1) = self.bounds
            if not (x0 < x1 and y0 < y1):
                raise ValueError("bounds: must be [[xmin, ymin], [xmax, ymax]] with xmin < xmax, ymin < ymax")
            for name, (x, y) in (("start", self.start), ("goal", self.goal)):
                if not (x0 <= x <= x1 and y0 <= y <= y1):
                    raise ValueError(f"{name}: lies outside bounds")
        problem = reach(self.planner.to_params(), self.start, self.goal)  # the bound that needs both ends
        if problem is not None:
            raise ValueError(f"planner.step: {problem}")
        seen: set[str] = set()
        for i, t in enumerate(self.threats):
            tid = t.id or f"t{i + 1}"
            if tid in seen:
                raise ValueError(f"threats[{i}].id: duplicate id {tid!r}")
            seen.add(tid)
        zone_ids: set[str] = set()
        for i, z in enumerate(self.zones):
            zid = z.id or f"z{i + 1}"
            if zid in zone_ids:
                raise ValueError(f"zones[{i}].id: duplicate id {zid!r}")
            zone_ids.add(zid)
        check_teams(self.teams, None)  # a scenario's one unit has no id: any unit may be named

    def zone_set(self) -> ZoneSet:
        """The file's keep-out zones, for the core."""
        from pfp_service.core.zones import ZoneSet
        from pfp_service.world import translate

        return ZoneSet(translate.zone(z, z.id or f"z{i + 1}") for i, z in enumerate(self.zones))

    def schedule(self) -> list[Scheduled]:
        from pfp_service.core.plan import Scheduled

        return [Scheduled(t.to_threat(f"t{i + 1}"), t.appear_step) for i, t in enumerate(self.threats)]

    def bounds_tuple(self) -> tuple[tuple[float, float], tuple[float, float]] | None:
        if self.bounds is None:
            return None
        (x0, y0), (x1, y1) = self.bounds
        return (x0, y0), (x1, y1)


def decode_scenario(data: bytes, fmt: Literal["json", "yaml"], source: str = "") -> Scenario:
    """Decode and validate a scenario, within the file bounds (``bounds.LIMITS``).

    Raises:
        InputError: with the field path and the reason, or the limit passed.
    """
    return _convert(_document(data, fmt, source)[0], fmt, data)


def _document(data: bytes, fmt: Literal["json", "yaml"], source: str) -> tuple[object, yaml.Node | None]:
    """The parsed document and, for YAML, its node tree; JSON is scanned for its depth first."""
    if fmt == "json":
        bounds.scan_json(data, source, positions=bounds.limit("json_positions"))
        if b'"lat"' not in data and b'"lon"' not in data:
            return None, None  # nothing to localise: _convert decodes it straight into a Scenario
        try:
            return msgspec.json.decode(data), None
        except msgspec.DecodeError as exc:
            raise from_validation(exc, CHOICES) from exc
    try:
        return yamlio.parse(data, source)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}" if mark is not None else "file"
        problem = getattr(exc, "problem", None) or "invalid YAML"
        raise InputError(where, f"invalid YAML: {problem}") from exc


def _convert(obj: object, fmt: Literal["json", "yaml"], data: bytes) -> Scenario:
    if fmt == "json" and b'"lat"' not in data and b'"lon"' not in data:
        try:  # nothing to localise: msgspec decodes and validates in one pass
            return msgspec.json.decode(data, type=Scenario)
        except (msgspec.ValidationError, msgspec.DecodeError) as exc:
            raise from_validation(exc, CHOICES) from exc
    if not isinstance(obj, dict):
        raise InputError("", "a scenario must be a mapping with start, goal and threats")
    zones = obj.get("zones")
    if isinstance(zones, list) and any(isinstance(z, dict) for z in zones):
        origin = localise_document({"origin": obj["origin"]}).get("origin") if "origin" in obj else None
        obj = {
            **obj,
            "zones": [
                localise_zone(
                    z, msgspec.convert(origin, Origin) if origin is not None else None, f"zones[{i}]"
                )
                for i, z in enumerate(zones)
            ],
        }
    try:
        return msgspec.convert(localise_document(obj), Scenario)
    except msgspec.ValidationError as exc:
        raise from_validation(exc, CHOICES) from exc


def load_scenario(path: str | Path) -> Scenario:
    """Read a ``.yaml``/``.yml``/``.json`` scenario file.

    Raises:
        InputError: unreadable file, unknown suffix or invalid content.
    """
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix not in (".json", ".yaml", ".yml"):
        raise InputError(str(p), "scenario files must end in .yaml, .yml or .json")
    fmt: Literal["json", "yaml"] = "json" if suffix == ".json" else "yaml"
    data = read_text(p, bounds.limit("yaml_bytes" if fmt == "yaml" else "text_bytes")).encode()
    root = None
    try:
        obj, root = _document(data, fmt, p.name)
        scenario = _convert(obj, fmt, data)
    except InputError as err:
        raise _in_file(p, data, fmt, root, err) from None
    if scenario.terrain is not None and not Path(scenario.terrain).is_absolute():
        scenario = msgspec.structs.replace(scenario, terrain=str(p.parent / scenario.terrain))
    return scenario


def _in_file(
    p: Path, data: bytes, fmt: Literal["json", "yaml"], root: yaml.Node | None, err: InputError
) -> InputError:
    """``err`` naming the file, and the line of its field, as team and script files do."""
    if err.path == p.name or err.path.startswith(f"{p.name} "):  # a bound, naming the file already
        return err
    if err.path.startswith("line "):  # a YAML syntax error knows its line and column
        return InputError(f"{p.name} {err.path}", err.reason)
    if not err.path and fmt == "json":  # malformed JSON: msgspec names a byte offset, or the end
        at = re.search(r"\(byte (\d+)\)", err.reason)
        end = len(data.rstrip()) if at is None or "truncated" in err.reason else int(at[1])
        line = data[:end].count(b"\n") + 1
        return InputError(f"{p.name} line {line}", err.reason)
    if fmt == "json":  # the tokens give a field's line; the file is never parsed again as YAML
        field_line = bounds.json_line_of(data.decode(), err.path)
        where = f"{p.name} line {field_line}" if field_line is not None else p.name
        return InputError(f"{where}, {err.path}" if err.path else where, err.reason)
    return yamlio.located(p, root, err)
