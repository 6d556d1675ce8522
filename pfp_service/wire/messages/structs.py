"""The message Structs: every payload's shape and bounds, frozen and keyword-only.

The planner's events are in ``events``, what planners share (missions, the world's pages) in ``world``; decoding and encoding are in ``codec``;
``pfp_service.wire.messages`` exports them all.
"""

from __future__ import annotations

from collections.abc import Sequence
from enum import StrEnum
from typing import Annotated

import msgspec
from msgspec import Meta

from pfp_service.constraints import (
    Delta,
    Finite,
    Id,
    Iterations,
    NonNegative,
    Point,
    Positive,
    Sigma,
    Skew,
    Step,
    Tolerance,
    Weight,
    check_spreads,
)
from pfp_service.errors import InputError
from pfp_service.geo import Latitude, LatLon, Longitude, Origin
from pfp_service.wire.messages.guidance import Progress, RouteKind

__all__ = [
    "CHOICES",
    "CONTENT_TYPE",
    "MAX_EVENT_ITEMS",
    "MAX_LOOKAHEAD",
    "MAX_PAYLOAD_BYTES",
    "MAX_SNAPSHOT_ITEMS",
    "MAX_WHATIF_THREATS",
    "MAX_WORLD_QUERY_CHARS",
    "MAX_ZONE_EXTENT_M",
    "MAX_ZONE_RINGS",
    "MAX_ZONE_VERTICES",
    "SNAPSHOT_PAGE_BYTES",
    "TEXT_MAX_CHARS",
    "Bounds",
    "Direction",
    "DirectionStatus",
    "ErrorReply",
    "Goal",
    "GoalMobility",
    "LatLon",
    "Origin",
    "PlannerStatus",
    "PreviewRequest",
    "TerrainInfo",
    "ThreatUpdate",
    "UnitKind",
    "UnitState",
    "WhatIfThreat",
    "ZoneCircle",
    "ZoneUpdate",
    "fit_text",
]

# The MIME type of every payload; ``pfp_service.wire.encoding.zenoh_encoding()`` maps it to Zenoh's.
CONTENT_TYPE = "application/json"
# Largest payload a decoder reads.  The biggest legitimate message, a preview
# request with MAX_WHATIF_THREATS threats, is about 60 KiB.
MAX_PAYLOAD_BYTES = 256 * 1024
MAX_WHATIF_THREATS = 256
MAX_LOOKAHEAD = 1000
MAX_EVENT_ITEMS = 64  # ids listed in one event; the rest are counted
MAX_SNAPSHOT_ITEMS = 1000  # units, threats or zones listed in one world reply (one page)
# A world reply's units and threats stop short of this many bytes of JSON, so a page always
# decodes (MAX_PAYLOAD_BYTES) with room for the envelope: 1,000 units with missions are ~680 KB.
SNAPSHOT_PAGE_BYTES = 192 * 1024
MAX_WORLD_QUERY_CHARS = 1024  # the longest world query parameters read; longer is refused

# ((xmin, ymin), (xmax, ymax)) in metres, the same shape as core.stepper.Bounds.
Bounds = tuple[tuple[float, float], tuple[float, float]]

Angle = Annotated[float, Meta(ge=-360.0, le=360.0)]
# A threat's shape is named here and defined in the core's registry (``core.shapes``), which the wire
# cannot import: the wire checks the name's form and the planner whether it knows it.
DEFAULT_SHAPE = "skew_normal"
ShapeName = Annotated[str, Meta(pattern="^[a-z][a-z0-9_]{0,31}$")]
ShapeParams = Annotated[dict[ShapeName, Finite], Meta(max_length=16)]
Speed = Annotated[float, Meta(ge=0.0, le=1000.0)]
# Sender's clock in seconds (Unix time or any epoch it likes); not checked against ours.
Time = Annotated[float, Meta(ge=0.0, le=1e11)]
# Sequence numbers stay within JSON's exactly representable integers.
Seq = Annotated[int, Meta(ge=0, le=2**53 - 1)]
Count = Annotated[int, Meta(ge=0, le=2**53 - 1)]
TEXT_MAX_CHARS = 1024
Text = Annotated[str, Meta(max_length=TEXT_MAX_CHARS)]


def fit_text(text: str, limit: int = TEXT_MAX_CHARS) -> str:
    """``text`` if it fits a ``Text`` field, else its start ending in "…" (``limit`` characters in all)."""
    return text if len(text) <= limit else text[: limit - 1] + "…"


class UnitKind(StrEnum):
    MANNED = "manned"
    UNMANNED = "unmanned"


class DirectionStatus(StrEnum):
    """What a direction means for the unit receiving it."""

    EN_ROUTE = "en_route"
    ESCAPING = "escaping"
    ARRIVED = "arrived"
    TRAPPED = "trapped"
    NO_GOAL = "no_goal"
    YIELDING = "yielding"  # holding: right of way to a friendly unit (dispersion); goes when it has passed


# The ``reason`` of a ``no_goal`` direction once a delete on the wire took the unit's goal: a client
# that puts its goal again on ``no_goal`` (a restarted planner says nothing) leaves this one be.
GOAL_CANCELLED = "goal cancelled"

CHOICES: dict[str, tuple[str, ...]] = {
    "kind": tuple(k.value for k in UnitKind),
    "status": tuple(s.value for s in DirectionStatus),
    "route": tuple(r.value for r in RouteKind),
    "progress": tuple(p.value for p in Progress),
}


class _Message(msgspec.Struct, frozen=True, kw_only=True):
    """Base of every wire message: frozen, keyword-only, unknown fields ignored."""


# -- unit -> planner ------------------------------------------------------------
MobilityName = Annotated[str, Meta(pattern="^[a-z][a-z0-9_]{0,31}$")]
SlopeDeg = Annotated[float, Meta(ge=1.0, le=89.0)]
UNIT_HEIGHT_M = (0.1, 20.0)  # a person lying down to a mast on a vehicle
FLAT_SPEED_MPS = (0.1, 40.0)  # a crawl to a wheeled vehicle on a road
UnitHeight = Annotated[float, Meta(ge=UNIT_HEIGHT_M[0], le=UNIT_HEIGHT_M[1])]
FlatSpeed = Annotated[float, Meta(ge=FLAT_SPEED_MPS[0], le=FLAT_SPEED_MPS[1])]


class GoalMobility(_Message, frozen=True, kw_only=True):
    """A unit's mobility class, on its goal or its state: the ground it can cross (``core.mobility.CLASSES``).

    Attributes:
        kind: the class, ``foot``, ``wheeled`` or ``tracked`` (JSON ``class``); a name the
            planner does not know is refused on the goal's or the state's key (field ``$.mobility.class``).
        max_slope_deg: the steepest ground it climbs, degrees (1 to 89), over the class's, planned to
            the whole degree (at the steepest class limit not above it until the planner has built its
            barriers, off its loop; it refuses one below every class's limit).
        height_m: how tall it stands, metres (0.1 to 20), over the class's: what a threat over
            terrain must see of it, and its end of a controller's link.
        speed_mps: its speed on the flat, metres per second (0.1 to 40), over the class's: what its
            time over the ground is reckoned at (on a slope, the class's model scales it).
    """

    kind: MobilityName = msgspec.field(name="class")
    max_slope_deg: SlopeDeg | None = None
    height_m: UnitHeight | None = None
    speed_mps: FlatSpeed | None = None


class UnitState(_Message, frozen=True, kw_only=True):
    """Where a unit is; published on ``mumt/{m}/unit/{u}/state``.

    Attributes:
        position: ``[x, y]`` in metres (x east, y north), or ``{"lat", "lon"}`` in WGS-84
            degrees when the planner has a mission origin.
        t: the sender's time of the fix in seconds, if it has one.
        seq: the sender's sequence number; the direction answering it echoes it.
        kind: ``manned`` or ``unmanned``.
        speed_mps: ground speed in metres per second.
        heading_deg: compass heading in degrees, clockwise from north.
        mobility: the unit's standing mobility class over terrain (``GoalMobility``), kept until
            a state names another (a state without it changes nothing); a goal's own ``mobility``
            overrides it for that goal.  A class the planner does not know refuses the state
            (field ``$.mobility.class``).
    """

    position: Point
    t: Time | None = None
    seq: Seq | None = None
    kind: UnitKind | None = None
    speed_mps: Speed | None = None
    heading_deg: Angle | None = None
    mobility: GoalMobility | None = None


class Goal(_Message, frozen=True, kw_only=True):
    """Where a unit should go; put on ``mumt/{m}/unit/{u}/goal``, a DELETE cancels it.

    Attributes:
        position: ``[x, y]`` in metres (x east, y north), or ``{"lat", "lon"}`` in WGS-84
            degrees when the planner has a mission origin.
        delta: goal weight (1e-9 to 1e9); derived by the scale-free rule when absent.
        tolerance: arrival radius in metres (>= 0.001); derived when absent.
        step: a planning-resolution hint in metres (>= 0.001); derived when absent,
            as a vehicle should leave it: guidance holds whatever the vehicle does
            between two reports, at any rate and speed.  A step that would need
            more than ``max_iter`` steps to reach the goal from where the unit is
            is refused when the mission is fixed (a ``rejected`` event on the
            goal's key, field ``$.step``).
        mobility: the unit's mobility class over terrain for this goal (``GoalMobility``): its slope
            limit makes the barriers it plans around; absent, the class its states name, else the
            planner's ``--terrain-unit``.
    """

    position: Point
    delta: Delta | None = None
    tolerance: Tolerance | None = None
    step: Step | None = None
    mobility: GoalMobility | None = None


class ThreatUpdate(_Message, frozen=True, kw_only=True):
    """A threat, put on ``mumt/{m}/threat/{t}`` (the id is the key's last chunk); a DELETE removes it.

    Attributes:
        position: the enemy position, ``[x, y]`` in metres or ``{"lat", "lon"}`` in WGS-84
            degrees when the planner has a mission origin.
        shape: the kind of threat (``core.shapes``): ``skew_normal`` (the default) or ``area``;
            a name the planner does not know is refused on the threat's key (field ``$.shape``).
        facing_deg: the direction it faces, compass degrees (``skew_normal``).
        sigma_range: spread along the facing, metres (>= 0.001); required by ``skew_normal``.
        sigma_lateral: spread across the facing, metres (>= 0.001); required by ``skew_normal``.
        skew: how far the threat reaches forward rather than back (0 = symmetric, <= 1000).
        params: every other shape's parameters by name, e.g. ``{"radius_m": 300}`` for ``area``
            (the skew-normal's are the four fields above).
        weight: how much it matters (0 to 1e6).
        ttl_s: seconds until it expires unless put again; absent = until deleted.
    """

    position: Point
    shape: ShapeName = DEFAULT_SHAPE
    facing_deg: Angle = 0.0
    sigma_range: Sigma | None = None
    sigma_lateral: Sigma | None = None
    skew: Skew = 0.0
    params: ShapeParams | None = None
    weight: Weight = 1.0
    ttl_s: Positive | None = None

    def __post_init__(self) -> None:
        if self.shape != DEFAULT_SHAPE:
            return  # its params are the shape's to check (world/translate.py)
        if self.sigma_range is None:
            raise ValueError("sigma_range: is required by the skew_normal shape")
        if self.sigma_lateral is None:
            raise ValueError("sigma_lateral: is required by the skew_normal shape")
        if self.params:
            raise ValueError("params: the skew_normal shape takes its fields at the top level")
        check_spreads(self.sigma_range, self.sigma_lateral)


# -- keep-out zones ------------------------------------------------------------------
MAX_ZONE_VERTICES = 4096  # over all of a zone's rings (``core.zones.MAX_VERTICES``)
MAX_ZONE_RINGS = 64  # the shell and its holes (``core.zones.MAX_RINGS``)
MAX_ZONE_EXTENT_M = 200_000.0  # a zone's bounding box, either side; a circle's diameter
ZoneKind = Annotated[str, Meta(pattern="^keep_out$")]  # room for later kinds
Ring = Annotated[list[Point], Meta(min_length=4, max_length=MAX_ZONE_VERTICES + 1)]


class ZoneCircle(_Message, frozen=True, kw_only=True):
    """A circular zone: its centre (``[x, y]`` metres or ``{lat, lon}``) and radius in metres."""

    centre: Point
    radius_m: Annotated[float, Meta(gt=0.0, le=MAX_ZONE_EXTENT_M / 2)]


class ZoneUpdate(_Message, frozen=True, kw_only=True):
    """A keep-out zone, put on ``mumt/{m}/zone/{z}`` (the id is the key's last chunk); a DELETE removes it.

    Exactly one of ``polygon`` and ``circle``.  No unit's path enters a zone
    (its boundary included).

    Attributes:
        kind: what the zone means; ``keep_out`` (the only kind so far).
        polygon: rings of vertices, the outer ring first and then its holes, as
            in GeoJSON: each ring closed (its last vertex repeats its first),
            none crossing itself, the holes inside the outer ring; each vertex
            ``[x, y]`` metres or ``{"lat": …, "lon": …}``.  At most
            ``MAX_ZONE_RINGS`` rings and ``MAX_ZONE_VERTICES`` vertices in all,
            within ``MAX_ZONE_EXTENT_M`` metres either way.
        circle: a circle instead of a polygon.
        ttl_s: seconds until it expires unless put again; absent = until deleted.
    """

    kind: ZoneKind = "keep_out"
    polygon: Annotated[list[Ring], Meta(min_length=1, max_length=MAX_ZONE_RINGS)] | None = None
    circle: ZoneCircle | None = None
    ttl_s: Positive | None = None

    def __post_init__(self) -> None:
        if (self.polygon is None) == (self.circle is None):
            raise ValueError("polygon: give exactly one of polygon and circle")
        if self.polygon is not None:
            _check_rings(self.polygon)


def _check_rings(rings: Sequence[Sequence[tuple[float, float]]]) -> None:
    """Closed, simple rings, bounded in count and extent, that make a valid polygon (GEOS says why not).

    Raises:
        ValueError: ``polygon[i]: reason`` (or ``polygon: reason`` for the polygon as a whole).
    """
    import shapely
    from shapely.validation import explain_validity

    total = sum(len(r) - 1 for r in rings)
    if total > MAX_ZONE_VERTICES:
        raise ValueError(f"polygon: {total} vertices, more than the {MAX_ZONE_VERTICES} a zone may have")
    for i, ring in enumerate(rings):
        if tuple(ring[0]) != tuple(ring[-1]):
            raise ValueError(f"polygon[{i}]: a ring must be closed (its last vertex repeats its first)")
        if len(set(ring)) < 3:
            raise ValueError(f"polygon[{i}]: a ring needs at least 3 distinct vertices")
        xs = [p[0] for p in ring]
        ys = [p[1] for p in ring]
        if max(xs) - min(xs) > MAX_ZONE_EXTENT_M or max(ys) - min(ys) > MAX_ZONE_EXTENT_M:
            raise ValueError(f"polygon[{i}]: wider than {MAX_ZONE_EXTENT_M:g} m")
        lr = shapely.LinearRing(ring)
        if not lr.is_simple:
            raise ValueError(
                f"polygon[{i}]: the ring crosses itself ({explain_validity(shapely.Polygon(ring))})"
            )
    poly = shapely.Polygon(rings[0], rings[1:])
    if not poly.is_valid:
        raise ValueError(f"polygon: not a valid polygon: {explain_validity(poly)}")
    if poly.area <= 0.0:
        raise ValueError("polygon: the polygon has no area")


class WhatIfThreat(ThreatUpdate, frozen=True, kw_only=True):
    """A hypothetical threat in a preview request; it carries its own id."""

    id: Id


def _duplicate_ids(threats: Sequence[WhatIfThreat]) -> None:
    seen: set[str] = set()
    for i, t in enumerate(threats):
        if t.id in seen:
            raise ValueError(f"threats[{i}].id: duplicate id {t.id!r}")
        seen.add(t.id)


class PreviewRequest(_Message, frozen=True, kw_only=True):
    """Optional body of a query on ``mumt/{m}/preview/{u}``.

    No body (or ``{}``) previews the unit's live state to its live goal.  Any
    field given makes it a what-if: ``start`` and ``goal`` replace the unit's,
    ``threats`` are added to the live ones, and the live world is unchanged.
    ``geojson: true`` asks for the reply as an RFC 7946 FeatureCollection
    (``pfp_service.geojson``) instead of the plan object; it needs a mission
    origin, and by itself it does not make the preview a what-if.
    """

    start: Point | None = None
    goal: Point | None = None
    threats: Annotated[list[WhatIfThreat], Meta(max_length=MAX_WHATIF_THREATS)] = []
    delta: Delta | None = None
    step: Step | None = None
    tolerance: Tolerance | None = None
    max_iter: Iterations | None = None
    geojson: bool = False

    def __post_init__(self) -> None:
        _duplicate_ids(self.threats)

    @property
    def what_if(self) -> bool:
        """True when anything was asked beyond the live preview (the reply's form does not count)."""
        return self != PreviewRequest(geojson=self.geojson)


# -- planner -> unit and replies ------------------------------------------------
class Direction(_Message, frozen=True, kw_only=True):
    """Which way to go; published on ``mumt/{m}/unit/{u}/direction``.

    Attributes:
        unit: the unit this is for.
        seq: the ``seq`` of the state it answers (null when it had none, or when
            a threat or goal change triggered it: then the latest seen).
        status: ``en_route | escaping | arrived | trapped | no_goal | yielding``.
        vector: unit vector ``[dx, dy]`` to move along; ``[0, 0]`` when not moving.
        heading_deg: the vector as a compass heading, null when not moving.
        distance_to_goal: metres, null without a goal.
        threat_level: weighted threat level at the unit's position.
        lookahead: the next positions the same stepper predicts, ``[[x, y], ...]``.
        reason: why, for ``trapped``, ``escaping`` and ``yielding``; for ``no_goal``, why the goal went
            (``goal cancelled``, ``goal refused: ...``, ``goal dropped: ...``; empty when none was held).
        true_bearing_deg: the vector as a bearing from true north at the unit,
            when the mission has an origin (``geo.with_geodetic``); null otherwise.
        lookahead_geo: ``lookahead`` as ``[{"lat", "lon"}, ...]`` when the mission has an origin.
        deliberating: a route for this unit is being computed off the planning
            loop; until it is adopted the vector is plain steepest descent.
        planner: the planner that computed it (several may share a mission).
        reach_m: how far along ``vector`` this direction stays good: on a route, to the point the
            unit is steered at (a few seconds of driving ahead at its own speed; the goal, on the
            final approach); before a route is chosen, one planner step; less where it stops
            short of a keep-out zone (0: hold here); null when not moving.  It is measured from
            the position in the state the direction answers (``seq``): a unit may drive at its own
            speed and should not go further than this before its next direction; one that has
            moved on since that report (a direction sent again, or late) drives to that leg's end.
        route: what the route behind the direction is (``descent``, ``lower_exposure``,
            ``around_trap``, ``escape``, ``leave``; empty before one is chosen).
        progress: what the unit's own reports show: ``moving``, ``holding`` (it said
            ``speed_mps`` 0), ``stalled`` (told to move, it has not); empty when unknown.
        route_left_m: metres still to drive along the route to the goal (an ETA is this over the
            unit's speed); null before a route is chosen, when ``distance_to_goal`` is the best known.
    """

    unit: Id
    seq: Seq | None = None
    status: DirectionStatus
    vector: Point
    heading_deg: Angle | None = None
    distance_to_goal: NonNegative | None = None
    threat_level: NonNegative = 0.0
    lookahead: Annotated[list[Point], Meta(max_length=MAX_LOOKAHEAD)] = []
    reason: Text = ""
    deliberating: bool = False
    planner: Id | None = None
    true_bearing_deg: Angle | None = None
    lookahead_geo: Annotated[list[LatLon], Meta(max_length=MAX_LOOKAHEAD)] = []
    reach_m: NonNegative | None = None
    route: RouteKind = RouteKind.NONE
    progress: Progress = Progress.UNKNOWN
    route_left_m: NonNegative | None = None


class ErrorReply(_Message, frozen=True, kw_only=True):
    """The ``reply_err`` body for a bad query: the reason and the field path."""

    error: Text
    field: Text = "$"

    @classmethod
    def of(cls, exc: InputError) -> ErrorReply:
        return cls(error=fit_text(exc.reason), field=fit_text(exc.path or "$"))


class TerrainInfo(msgspec.Struct, frozen=True, kw_only=True):
    """The DEM a planner plans over (``PlannerStatus.terrain``): planners of one mission must share it."""

    file: Text  # the file's name, without its directory
    sha256: Annotated[str, Meta(pattern="^[0-9a-f]{64}$")]
    south: Latitude
    west: Longitude
    north: Latitude
    east: Longitude
    resolution_m: Positive  # the planner's terrain cell
    unit: Text  # the mobility class planned for (core.mobility): its height and slope limit
    origin_centred: bool = False  # the mission origin is the DEM's centre (none was given)


class PlannerStatus(_Message, frozen=True, kw_only=True):
    """Reply of ``mumt/{m}/planner/{p}/status``: health and counters."""

    planner: Id
    mission: Id
    version: Text = ""
    uptime_s: NonNegative
    units: Count = 0
    units_stale: Count = 0
    threats: Count = 0
    zones: Count = 0  # keep-out zones in force
    msgs_in: Count = 0
    msgs_out: Count = 0
    rejected: Count = 0
    latency_p50_ms: NonNegative | None = None
    latency_p99_ms: NonNegative | None = None
    deliberating: Count = 0
    overload: Count = 0
    units_owned: Count = 0  # units this planner guides (all of them unless several share the mission)
    pushes: Count = 0  # directions sent without a report asking (world changes, routes landing)
    pushes_resent: Count = 0  # ... sent again, because no report has been answered since
    session: Text = ""  # the planner's Zenoh session id: planners that share an id are told apart by it
    origin: Origin | None = None  # where its [0, 0] lies; clients check or convert their own against it
    faults: Count = 0  # inputs dropped because applying them failed inside the planner (each also rejected)
    # twins: other planners this one sees answering the same units (another id while not --cluster, or a
    # second session under its own id), each "ID" or "ID-SESSION"; pfp status and pfp health warn of them
    twins: Annotated[tuple[Text, ...], Meta(max_length=64)] = ()
    terrain: TerrainInfo | None = None  # the DEM planned over (pfp serve --terrain); none: flat, open ground
