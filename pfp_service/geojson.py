"""GeoJSON export (RFC 7946): a plan, its threats and their zones as one FeatureCollection.

Coordinates are ``[lon, lat]`` WGS-84 degrees rounded to ``DECIMALS`` (1e-7
degrees, about a centimetre), from planner metres through the mission
``Origin``.  Over terrain (an ``elevation`` sampler, ``pfp plan --terrain``),
the path, start, goal and threat points are ``[lon, lat, elevation]``: metres
on the DEM's vertical datum, rounded to ``Z_DECIMALS``; zones stay flat.  The collection holds:

- the path as a LineString (``kind: path``) with the plan's metrics;
- the start and the goal as Points (``kind: start`` / ``goal``);
- each threat as a Point at its position (``kind: threat``) with its parameters;
- each threat's zone (``kind: zone``), the region where its own level is at
  least ``level`` of its peak (default 10 %), and its core (``kind: core``), the
  half-maximum region the escapes never enter (``core.cores.CORE_FRACTION``);
- each keep-out zone (``kind: keep_out``, ``core.zones``) as a Polygon with its
  holes (a circle as a ``CIRCLE_VERTICES``-gon round it, with ``radius_m``).

The other way, ``zones_from_geojson`` reads keep-out zones from RFC 7946
Polygons and MultiPolygons (bare, in a Feature or a FeatureCollection) with
shapely, which checks each ring (closed, not crossing itself, holes inside);
``load_zones`` reads a file of them (``pfp plan --zones``, ``pfp serve --zones``).

Zones are traced as polygons of ``ZONE_VERTICES`` points: a skew-normal
density is log-concave, so each level set is convex and every ray from the
mode crosses its boundary once, found by bisection.  Rings are closed and run
counter-clockwise (the right-hand rule of RFC 7946 section 3.1.6).  The
module computes values; only ``write`` (``pfp plan --geojson``) and ``load_zones`` touch the file system.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import msgspec
import numpy as np

from pfp_service import bounds
from pfp_service.errors import InputError
from pfp_service.geo import LatLon, Origin

if TYPE_CHECKING:
    # The core is imported where it is used: reading a zones file, and refusing a hostile one,
    # must not compile it (issue 35: a refusal stays light).
    from pfp_service.core.plan import PlanResult
    from pfp_service.core.threat import Threat
    from pfp_service.core.zones import Zone
    from pfp_service.scenario import Scenario

__all__ = [
    "CIRCLE_VERTICES",
    "DECIMALS",
    "ZONE_LEVEL",
    "ZONE_VERTICES",
    "check_geojson_path",
    "feature_collection",
    "load_zones",
    "preview_reply",
    "scenario_collection",
    "write",
    "zone_ring",
    "zones_from_geojson",
]

DECIMALS = 7
Z_DECIMALS = 2  # centimetres: finer than any DEM's heights are known
Elevation = Callable[[np.ndarray, np.ndarray], np.ndarray]
ZONE_LEVEL = 0.1
ZONE_VERTICES = 96
CIRCLE_VERTICES = 72
METRICS = (
    "status",
    "reason",
    "steps",
    "length",
    "exposure",
    "peak_threat",
    "min_clearance",
    "final_distance",
)


def zone_ring(t: Threat, level: float, vertices: int = ZONE_VERTICES) -> np.ndarray:
    """The boundary of ``{x : t(x) >= level * max t}`` as ``(vertices, 2)`` metres, counter-clockwise.

    Args:
        t: a threat of positive weight.
        level: the share of the peak, strictly between 0 and 1.
        vertices: points on the ring (it is not closed here).

    Raises:
        ValueError: ``level`` outside (0, 1) or a weightless threat (it has no zone).
    """
    from pfp_service.core.shapes import level_ring

    return level_ring(t, level, vertices)


def _lonlat(origin: Origin, xy: np.ndarray, elevation: Elevation | None = None) -> list[list[float]]:
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    ll = origin.to_geodetic_many(xy)
    z = elevation(xy[:, 0], xy[:, 1]) if elevation is not None else None
    out: list[list[float]] = []
    for k, (lat, lon) in enumerate(ll):
        p = [round(float(lon), DECIMALS), round(float(lat), DECIMALS)]
        if out and p == out[-1][:2]:  # rounding may merge neighbours; a ring repeats only its first
            continue
        if z is not None and math.isfinite(z[k]):  # unknown ground: no height rather than a made-up one
            p.append(round(float(z[k]), Z_DECIMALS))
        out.append(p)
    return out


def _ring(origin: Origin, xy: np.ndarray) -> list[list[float]]:
    ring = _lonlat(origin, xy)
    if ring[-1] == ring[0]:
        ring.pop()
    return [*ring, ring[0]]


def _feature(geometry: dict[str, Any], properties: dict[str, Any]) -> dict[str, Any]:
    return {"type": "Feature", "geometry": geometry, "properties": properties}


def _point(
    origin: Origin, xy: Sequence[float], properties: dict[str, Any], elevation: Elevation | None = None
) -> dict[str, Any]:
    (coords,) = _lonlat(origin, np.array([xy]), elevation)
    return _feature({"type": "Point", "coordinates": coords}, properties)


def feature_collection(
    origin: Origin,
    threats: Sequence[Threat],
    result: PlanResult | None = None,
    *,
    start: Sequence[float] | None = None,
    goal: Sequence[float] | None = None,
    level: float = ZONE_LEVEL,
    threat_properties: Mapping[str, Mapping[str, Any]] | None = None,
    name: str = "",
    zones: Sequence[Zone] = (),
    elevation: Elevation | None = None,
) -> dict[str, Any]:
    """The RFC 7946 FeatureCollection of a plan (as a dict for ``json.dumps``).

    Args:
        origin: the mission origin; every position is metres from it.
        threats: the threats to draw (points, zones and cores).
        result: the plan, drawn as a LineString with its metrics; ``None`` draws threats only.
        start: the start, drawn as a Point when given.
        goal: the goal, drawn as a Point when given.
        level: the zone's share of each threat's peak, strictly between 0 and 1.
        threat_properties: extra properties by threat id (e.g. the file's facing and sigmas).
        name: the collection's name (a foreign member, as RFC 7946 section 6.1 allows).
        zones: keep-out zones, drawn as Polygons (``kind: keep_out``).
        elevation: ground height in metres at planner ``(x, y)`` arrays (``TerrainGrid.elevation``):
            the path and the points get it as a third coordinate, where it is known.

    Raises:
        ValueError: ``level`` outside (0, 1).
    """
    if not 0.0 < level < 1.0:
        raise ValueError(f"level: must be strictly between 0 and 1, got {level}")
    features: list[dict[str, Any]] = []
    if result is not None and len(result.path) >= 2:
        props: dict[str, Any] = {"kind": "path"}
        for k in METRICS:
            v = getattr(result, k)
            props[k] = v.value if hasattr(v, "value") else v
        props["compute_ms"] = result.compute_ms
        line = _lonlat(origin, np.asarray(result.path), elevation)
        if len(line) < 2:  # a path shorter than the rounding: still a valid LineString
            line = [line[0], line[0]]
        features.append(_feature({"type": "LineString", "coordinates": line}, props))
    if start is not None:
        features.append(_point(origin, start, {"kind": "start"}, elevation))
    if goal is not None:
        features.append(_point(origin, goal, {"kind": "goal"}, elevation))
    extra = threat_properties or {}
    for t in threats:
        tp: dict[str, Any] = {
            "kind": "threat",
            "id": t.id,
            "weight": t.weight,
            "omega": [list(t.omega[0]), list(t.omega[1])],
            "alpha": list(t.alpha),
            **extra.get(t.id, {}),
        }
        features.append(_point(origin, t.xi, tp, elevation))
        if t.weight <= 0.0:
            continue
        from pfp_service.core.cores import CORE_FRACTION

        for kind, share in (("zone", level), ("core", CORE_FRACTION)):
            ring = _ring(origin, zone_ring(t, share))
            features.append(
                _feature(
                    {"type": "Polygon", "coordinates": [ring]}, {"kind": kind, "id": t.id, "level": share}
                )
            )
    for z in zones:
        features.append(_keep_out(origin, z))
    out: dict[str, Any] = {"type": "FeatureCollection", "features": features}
    if name:
        out["name"] = name
    return out


def _keep_out(origin: Origin, z: Zone) -> dict[str, Any]:
    """A keep-out zone's Feature: its rings counter-clockwise, holes clockwise (RFC 7946 section 3.1.6)."""
    props: dict[str, Any] = {"kind": "keep_out", "id": z.id, "zone_kind": z.kind}
    if z.centre is not None:
        theta = 2.0 * math.pi * np.arange(CIRCLE_VERTICES) / CIRCLE_VERTICES
        r = z.radius_m / math.cos(math.pi / CIRCLE_VERTICES)  # the polygon holds the circle
        ring = np.column_stack([z.centre[0] + r * np.cos(theta), z.centre[1] + r * np.sin(theta)])
        props.update(radius_m=z.radius_m)
        return _feature({"type": "Polygon", "coordinates": [_ring(origin, ring)]}, props)
    rings = []
    for i, ring_m in enumerate(z.rings()):
        xy = np.asarray(ring_m, dtype=float)
        ccw = _signed_area(xy) > 0.0
        if ccw != (i == 0):
            xy = xy[::-1]
        rings.append(_ring(origin, xy))
    return _feature({"type": "Polygon", "coordinates": rings}, props)


def _signed_area(xy: np.ndarray) -> float:
    x, y = xy[:, 0], xy[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def zones_from_geojson(doc: Any, origin: Origin, source: str = "") -> list[Zone]:
    """Keep-out zones from a GeoJSON document: every Polygon and MultiPolygon in it.

    A Feature's zone id is its ``id`` or ``properties.id`` (or ``name``) when
    that is 1-64 of ``[A-Za-z0-9_-]``, else ``zone-N`` (N counting polygons
    from 1); a MultiPolygon's polygons get ``-1``, ``-2``, ... after it.
    Coordinates are ``[lon, lat]`` (an altitude is ignored), turned into
    metres from ``origin``.

    Raises:
        InputError: at ``source`` and the feature (``features[2].geometry``), with the reason.
    """
    import re

    import shapely.geometry
    from shapely.validation import explain_validity

    from pfp_service.core.zones import Zone

    def fail(where: str, reason: str) -> InputError:
        return InputError(f"{source}: {where}" if source and where else source or where, reason)

    if not isinstance(doc, dict):
        raise fail("", "expected a GeoJSON object (FeatureCollection, Feature, Polygon or MultiPolygon)")
    kind = doc.get("type")
    if kind == "FeatureCollection":
        items = doc.get("features")
        if not isinstance(items, list):
            raise fail("features", "expected a list of Features")
        feats = [(f"features[{i}]", f) for i, f in enumerate(items)]
    elif kind == "Feature":
        feats = [("", doc)]
    elif kind in ("Polygon", "MultiPolygon"):
        feats = [("", {"type": "Feature", "geometry": doc})]
    else:
        raise fail("type", f"expected FeatureCollection, Feature, Polygon or MultiPolygon, got {kind!r}")
    chunk = re.compile(r"^[A-Za-z0-9_-]{1,64}$")
    zones: list[Zone] = []
    seen: set[str] = set()
    for where, f in feats:
        at = f"{where}.geometry" if where else "geometry"
        if not isinstance(f, dict) or f.get("type") != "Feature":
            raise fail(where or "$", "expected a Feature")
        geom = f.get("geometry")
        if not isinstance(geom, dict) or geom.get("type") not in ("Polygon", "MultiPolygon"):
            got = geom.get("type") if isinstance(geom, dict) else geom
            raise fail(at, f"a keep-out zone must be a Polygon or MultiPolygon, got {got!r}")
        try:
            shape = shapely.geometry.shape(geom)
        except Exception as exc:  # shapely's own words for malformed coordinates
            raise fail(at, f"not a valid {geom['type']}: {exc}") from None
        if shape.is_empty:
            raise fail(at, "the geometry is empty")
        if not shape.is_valid:
            raise fail(at, f"not a valid {geom['type']}: {explain_validity(shape)}")
        raw_props = f.get("properties")
        props: dict[str, Any] = raw_props if isinstance(raw_props, dict) else {}
        name = next(
            (
                str(v)
                for v in (f.get("id"), props.get("id"), props.get("name"))
                if v is not None and chunk.match(str(v))
            ),
            "",
        )
        polys = list(shape.geoms) if shape.geom_type == "MultiPolygon" else [shape]
        for k, poly in enumerate(polys):
            zid = (f"{name}-{k + 1}" if len(polys) > 1 else name) if name else f"zone-{len(zones) + 1}"
            if zid in seen:
                raise fail(where or "$", f"zone id {zid!r} is given twice")
            seen.add(zid)
            rings = []
            for ring in (poly.exterior, *poly.interiors):
                ll = np.asarray(ring.coords, dtype=float)[:, :2]
                if not (np.all(np.abs(ll[:, 1]) <= 90.0) and np.all(np.abs(ll[:, 0]) <= 180.0)):
                    raise fail(
                        at, "coordinates must be [lon, lat] in degrees (lat within ±90, lon within ±180)"
                    )
                xy = [origin.localise_point(LatLon(lat=float(la), lon=float(lo)), at) for lo, la in ll]
                rings.append(xy)
            try:
                zones.append(Zone.polygon(zid, rings[0], rings[1:]))
            except ValueError as exc:
                raise fail(at, str(exc)) from None
    if not zones:
        raise fail("", "no Polygon or MultiPolygon in it")
    return zones


def load_zones(path: str | Path, origin: Origin | None, what: str = "--zones") -> list[Zone]:
    """Keep-out zones from a GeoJSON file (``zones_from_geojson``).

    Raises:
        InputError: one line naming the file (and the feature): unreadable, not JSON, no origin, a bad polygon.
    """
    from pfp_service.files import read_text

    text = read_text(str(path))
    if origin is None:
        raise InputError(what, f"{path}: GeoJSON is in lon/lat and needs a mission origin ({{lat, lon}})")
    bounds.scan_json(text, str(path), positions=bounds.limit("json_positions"))  # before the parse
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(str(path), f"not JSON: {exc.msg} at line {exc.lineno}, column {exc.colno}") from None
    try:
        return zones_from_geojson(doc, origin, str(path))
    except InputError as err:
        raise _on_line(str(path), text, err) from None


def _on_line(source: str, text: str, err: InputError) -> InputError:
    """``err`` with the line of its field (``features[2].geometry``), as scenario and team errors name it."""
    field = err.path[len(source) + 2 :] if err.path.startswith(f"{source}: ") else ""
    line = bounds.json_line_of(text, field)  # one pass over the tokens; never parsed again
    if line is None:
        return err
    return InputError(f"{source} line {line}" + (f", {field}" if field else ""), err.reason)


def preview_reply(
    origin: Origin | None,
    result: PlanResult,
    threats: Sequence[Threat],
    start: Sequence[float] | None = None,
    goal: Sequence[float] | None = None,
    zones: Sequence[Zone] = (),
) -> bytes:
    """The body of a preview reply asked for with ``geojson: true``: the collection as JSON bytes.

    Raises:
        InputError: at ``$.geojson``, when the planner has no mission origin.
    """
    if origin is None:
        raise InputError("$.geojson", "needs the mission origin (pfp serve --origin LAT,LON)")
    fc = feature_collection(origin, threats, result, start=start, goal=goal, zones=zones)
    return json.dumps(fc, ensure_ascii=False).encode()


def check_geojson_path(path: str | Path, what: str = "--geojson") -> Path:
    """Refuse, before any work is done, an output path that cannot take GeoJSON.

    Raises:
        InputError: naming ``what``, when the suffix is not ``.geojson``/``.json`` or the folder is missing.
    """
    p = Path(path)
    if p.suffix.lower() not in (".geojson", ".json"):
        raise InputError(what, f"{path}: must end in .geojson or .json")
    if not p.parent.is_dir():
        raise InputError(what, f"{path}: folder {p.parent} does not exist")
    return p


def scenario_collection(
    scenario: Scenario,
    result: PlanResult | None,
    level: float = ZONE_LEVEL,
    zones: Iterable[Zone] | None = None,
    origin: Origin | None = None,
    elevation: Elevation | None = None,
) -> dict[str, Any]:
    """``feature_collection`` of a scenario file's plan, its threats carrying the file's parameters.

    ``zones``: the keep-out zones planned with (default: the file's own). ``origin``: where the
    plane was placed (default: the file's; over terrain without one, the DEM's centre).
    ``elevation``: the terrain's sampler, for ``[lon, lat, elevation]``.

    Raises:
        InputError: at ``origin``, when there is none (GeoJSON is WGS-84 only).
    """
    origin = origin if origin is not None else scenario.origin
    if origin is None:
        raise InputError("origin", "GeoJSON needs the scenario's origin: add origin: {lat: …, lon: …}")
    props: dict[str, dict[str, Any]] = {}
    for i, spec in enumerate(scenario.threats):
        user = {
            k: v
            for k, v in msgspec.structs.asdict(spec).items()
            if v is not None and k not in ("id", "position")
        }
        props[spec.id or f"t{i + 1}"] = user
    threats = [s.threat for s in scenario.schedule()]
    return feature_collection(
        origin,
        threats,
        result,
        start=scenario.start,
        goal=scenario.goal,
        level=level,
        threat_properties=props,
        name=scenario.name,
        zones=list(scenario.zone_set() if zones is None else zones),
        elevation=elevation,
    )


def write(path: str | Path, collection: dict[str, Any], what: str = "--geojson") -> None:
    """Write ``collection`` as UTF-8 JSON.

    Raises:
        InputError: naming ``what``, when the file cannot be written.
    """
    try:
        Path(path).write_text(json.dumps(collection, ensure_ascii=False) + "\n", encoding="utf-8")
    except OSError as exc:
        raise InputError(what, f"cannot write {path}: {exc.strerror or exc}") from None
