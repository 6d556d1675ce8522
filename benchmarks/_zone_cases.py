"""The keep-out zone family of ``pfp bench quality --family zones``, and its ground truth.

Drawn like ``bench._cases`` in a unit frame (start at the origin, goal at
``(1, 0)``), then scaled to a start-goal distance log-uniform in 10-30,000 m,
rotated and shifted.  Kinds, in rotation:

* ``zone-line``: one zone (a rectangle or a circle) across the straight line;
* ``zone-gap``: a wall of two zones across the line with one gap off the line;
* ``zone-corridor``: a corridor between two long zones along the line, bent
  by a third zone at its far end that leaves one side open;
* ``zone-u``: a U-shaped zone round the goal, open away from the start;
* ``zone-enclosure``: a ring (a polygon with a hole) round the start or the goal;
* ``zone-thin``: one to three thin zones (0.1-0.4 % of the distance wide) across the way;
* ``zone-threats``: a wall of threats across the line with a zone closing one end;
* ``zone-circles``: several overlapping circles across the line, open at one end.

Ground truth (``zone_reachability``) does not ask the planner or the
engine's zone kernels: shapely (GEOS) says which nodes of a fine raster lie
within a margin of a zone, ``Cores.raster`` (the threat rule) which lie in a
core, and 4-connected components say whether start and goal are joined.  The
margin is ``0.75`` of the raster spacing (so a thin zone always blocks a
node), and again plus ``AMBIGUITY_BAND`` of the distance; threat cores at the
fractions 0.48 and 0.52.  A case whose answer changes across these is
*ambiguous*.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import shapely
from scipy import ndimage

from benchmarks._cases import Case, Verdict, _component
from pfp_service.core.cores import Cores
from pfp_service.core.threat import Threat, ThreatField
from pfp_service.core.zones import Zone

__all__ = ["AMBIGUITY_BAND", "ZONE_KINDS", "generate_zones", "zone_reachability"]

ZONE_KINDS = (
    "zone-line",
    "zone-gap",
    "zone-corridor",
    "zone-u",
    "zone-enclosure",
    "zone-thin",
    "zone-threats",
    "zone-circles",
)
AMBIGUITY_BAND = 0.01  # of the start-goal distance
_RASTER_NODES = 700  # along the longer side of the ground-truth raster

# a zone in the unit frame: ("poly", shell, holes) or ("circle", (x, y), r)
_Shape = tuple[Any, ...]


def _rect(x0: float, y0: float, x1: float, y1: float) -> _Shape:
    return ("poly", [(x0, y0), (x1, y0), (x1, y1), (x0, y1)], [])


def _shapes(kind: str, rng: np.random.Generator) -> tuple[list[_Shape], list[tuple[float, ...]]]:
    """Zones and threats (``x, y, facing, sigma_r, sigma_l, skew``) of one case, in the unit frame."""
    threats: list[tuple[float, ...]] = []
    if kind == "zone-line":
        cx, cy = rng.uniform(0.35, 0.65), rng.uniform(-0.15, 0.15)
        if rng.uniform() < 0.5:
            w, h = rng.uniform(0.03, 0.12), rng.uniform(0.3, 0.8)
            return [_rect(cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2)], threats
        r = rng.uniform(0.12, 0.3)
        return [("circle", (cx, 0.6 * cy), r)], threats
    if kind == "zone-gap":
        cx, w = rng.uniform(0.35, 0.65), rng.uniform(0.03, 0.08)
        g, gy = rng.uniform(0.08, 0.16), rng.uniform(0.1, 0.3) * rng.choice([-1.0, 1.0])
        h = rng.uniform(0.8, 1.2)
        return [
            _rect(cx - w / 2, gy + g / 2, cx + w / 2, gy + g / 2 + h),
            _rect(cx - w / 2, gy - g / 2 - h, cx + w / 2, gy - g / 2),
        ], threats
    if kind == "zone-corridor":
        half, w = rng.uniform(0.05, 0.12), rng.uniform(0.05, 0.15)
        x0, x1 = rng.uniform(0.15, 0.3), rng.uniform(0.55, 0.7)
        side = rng.choice([-1.0, 1.0])
        plug = _rect(x1, -half - w, x1 + w, half + w)
        if side > 0:  # the far end is shut below the line, open above: a bend in the corridor
            plug = _rect(x1, -half - w, x1 + w, 0.3 * half)
        else:
            plug = _rect(x1, -0.3 * half, x1 + w, half + w)
        return [_rect(x0, half, x1, half + w), _rect(x0, -half - w, x1, -half), plug], threats
    if kind == "zone-u":
        r, w = rng.uniform(0.12, 0.2), rng.uniform(0.03, 0.06)
        gx = 1.0
        # the U's bottom faces the start; its arms run past the goal, away from the start
        shell = [
            (gx - r - w, -r - w),
            (gx + r, -r - w),
            (gx + r, -r),
            (gx - r, -r),
            (gx - r, r),
            (gx + r, r),
            (gx + r, r + w),
            (gx - r - w, r + w),
        ]
        return [("poly", shell, [])], threats
    if kind == "zone-enclosure":
        cx = 0.0 if rng.uniform() < 0.5 else 1.0
        r, w = rng.uniform(0.1, 0.25), rng.uniform(0.02, 0.06)
        outer = [(cx - r - w, -r - w), (cx + r + w, -r - w), (cx + r + w, r + w), (cx - r - w, r + w)]
        hole = [(cx - r, -r), (cx + r, -r), (cx + r, r), (cx - r, r)]
        return [("poly", outer, [hole])], threats
    if kind == "zone-thin":
        out: list[_Shape] = []
        for k in range(int(rng.integers(1, 4))):
            cx = 0.25 + 0.5 * (k + rng.uniform(0.2, 0.8)) / 3.0
            w, h = rng.uniform(0.001, 0.004), rng.uniform(0.3, 0.7)
            cy = rng.uniform(-0.2, 0.2)
            ang = math.radians(rng.uniform(-30, 30))
            c, s = math.cos(ang), math.sin(ang)
            pts = [(-w / 2, -h / 2), (w / 2, -h / 2), (w / 2, h / 2), (-w / 2, h / 2)]
            out.append(("poly", [(cx + c * x - s * y, cy + s * x + c * y) for x, y in pts], []))
        return out, threats
    if kind == "zone-threats":
        sig = rng.uniform(0.03, 0.045)
        wx, h = rng.uniform(0.4, 0.6), rng.uniform(0.2, 0.35)
        n = max(3, math.ceil(2 * h / (1.2 * sig)) + 1)
        for k in range(n):
            y = -h + 2 * h * k / (n - 1)
            threats.append(
                (wx, y, rng.uniform(0, 360), sig, sig * rng.uniform(0.85, 1.0), rng.uniform(0, 0.6))
            )
        side = rng.choice([-1.0, 1.0])
        w = rng.uniform(0.03, 0.08)
        y0, y1 = sorted((side * (h - sig), side * (h + rng.uniform(0.3, 0.6))))
        return [_rect(wx - w / 2, y0, wx + w / 2, y1)], threats
    if kind == "zone-circles":
        out = []
        cx, r = rng.uniform(0.4, 0.6), rng.uniform(0.05, 0.09)
        side = rng.choice([-1.0, 1.0])
        n = int(rng.integers(4, 7))
        for k in range(n):  # a chain of overlapping circles from past the line on one side, across it
            out.append(("circle", (cx + rng.uniform(-0.2, 0.2) * r, side * (r + 0.05 - 1.5 * r * k)), r))
        return out, threats
    raise ValueError(f"unknown zone kind {kind!r}")


def generate_zones(count: int, seed: int) -> list[Case]:
    """``count`` zone scenarios from ``seed``; the same arguments always give the same suite."""
    rng = np.random.default_rng([seed, 24])
    cases = []
    for i in range(count):
        kind = ZONE_KINDS[i % len(ZONE_KINDS)]
        shapes, specs = _shapes(kind, rng)
        scale = float(math.exp(rng.uniform(math.log(10.0), math.log(30_000.0))))
        phi = rng.uniform(0, 2 * math.pi)
        c, s = math.cos(phi), math.sin(phi)
        ox, oy = rng.uniform(-5, 5) * scale, rng.uniform(-5, 5) * scale

        def place(
            x: float, y: float, c: float = c, s: float = s, ox: float = ox, oy: float = oy
        ) -> tuple[float, float]:
            return (ox + scale * (c * x - s * y), oy + scale * (s * x + c * y))

        zones = []
        for k, sh in enumerate(shapes):
            zid = f"z{k + 1}"
            if sh[0] == "circle":
                (cx, cy), r = sh[1], sh[2]
                zones.append(Zone.circle(zid, place(cx, cy), scale * float(r)))
            else:
                shell, holes = sh[1], sh[2]
                zones.append(
                    Zone.polygon(
                        zid,
                        [place(x, y) for x, y in shell],
                        [[place(x, y) for x, y in h] for h in holes],
                    )
                )
        threats = tuple(
            Threat.from_facing(
                place(sp[0], sp[1]),
                (sp[2] - math.degrees(phi)) % 360,
                scale * sp[3],
                scale * sp[4],
                sp[5],
                1.0,
                f"t{j + 1}",
            )
            for j, sp in enumerate(specs)
        )
        cases.append(
            Case(
                f"z{i:02d}-{kind}", kind, place(0.0, 0.0), place(1.0, 0.0), threats, scale, None, tuple(zones)
            )
        )
    return cases


def _geometry(zone: Zone) -> shapely.Geometry:
    if zone.centre is not None:
        return shapely.Point(zone.centre).buffer(zone.radius_m, quad_segs=64)
    return shapely.Polygon(zone.shell, zone.holes)


def zone_reachability(case: Case) -> Verdict:
    """Is there a way from start to goal that enters no zone and no core, by shapely and a raster (not the planner)?"""
    (sx, sy), (gx, gy) = case.start, case.goal
    d0 = math.hypot(gx - sx, gy - sy)
    geoms = [_geometry(z) for z in case.zones]
    lo = np.array([min(sx, gx) - d0, min(sy, gy) - d0])
    hi = np.array([max(sx, gx) + d0, max(sy, gy) + d0])
    for g in geoms:  # the whole of every zone, and room round it
        b = np.array(g.bounds)
        lo, hi = np.minimum(lo, b[:2] - 0.2 * d0), np.maximum(hi, b[2:] + 0.2 * d0)
    h = float(max(hi - lo)) / _RASTER_NODES
    shape = (math.ceil((hi[0] - lo[0]) / h) + 1, math.ceil((hi[1] - lo[1]) / h) + 1)
    xs = lo[0] + h * np.arange(shape[0])
    ys = lo[1] + h * np.arange(shape[1])
    gxs, gys = np.meshgrid(xs, ys, indexing="ij")
    union = shapely.union_all(geoms) if geoms else None
    field = ThreatField([t for t in case.threats if t.weight > 0])
    answers = []
    for margin in (0.75 * h, 0.75 * h + AMBIGUITY_BAND * d0):
        zone_mask = np.zeros(shape, dtype=bool)
        if union is not None:
            grown = union.buffer(margin, quad_segs=16)
            shapely.prepare(grown)
            zone_mask = shapely.contains_xy(grown, gxs, gys)
        for f in (0.48, 0.52) if len(field) else (0.5,):
            cores = (
                Cores(field, f).raster((float(lo[0]), float(lo[1])), h, shape)
                if len(field)
                else np.zeros(shape, dtype=bool)
            )
            labels, _ = ndimage.label(~(zone_mask | cores))
            at_start = _component(labels, (sx - lo[0]) / h, (sy - lo[1]) / h)
            at_goal = _component(labels, (gx - lo[0]) / h, (gy - lo[1]) / h)
            answers.append(bool(at_start & at_goal))
    verdict = answers[0] if len(set(answers)) == 1 else None
    return Verdict(verdict, h, tuple(answers))
