"""The seeded scenario suite of ``pfp bench quality``, and its ground truth.

Every scenario is drawn in a unit frame (start at the origin, goal at
``(1, 0)``) and then scaled to a start-goal distance log-uniform in
10-30,000 m (``clutter``: 10-30 km), rotated and shifted at random, so the
suite exercises the scale-free rule as well as the traps.  A scenario with
mission bounds is rotated by a multiple of 90 degrees only, so the bounds stay
a box.  Kinds, in rotation:

* ``open``: 2-20 scattered threats, random facings and skews;
* ``horseshoe``: an arc of threats around the goal bearing, open towards the start;
* ``cup``: a U of three straight walls, open towards the start;
* ``wall``: a straight wall across the start-goal line, open at both ends;
* ``block``: one large unskewed threat (or a symmetric pair) square on the line;
* ``enclosure-start`` / ``enclosure-goal``: a closed ring round the start or
  the goal whose cores overlap, so no way avoids every core.

* ``corridor``: a channel between two lines of inward-facing skewed threats,
  along the start-goal line (descent runs down it; going round is cheaper);
* ``nested``: a cup behind a cup, both open towards the start;
* ``s-bend``: two walls from alternate sides inside tight mission bounds;
* ``shadow``: the goal just behind a strongly skewed threat facing the start;
* ``clutter``: 200-1,000 threats over the whole way;
* ``anisotropic``: needles (sigma_lateral / sigma_range 0.05, skew 10-50)
  making a wedge, or wide thin pancakes (ratio 8-20) in staggered slabs;
* ``gap-open`` / ``gap-shut``: a long wall with one gap whose middle is at
  0.35-0.45 (open by the core rule) or 0.55-0.65 (shut) of the neighbours' peak;
* ``ring-open`` / ``ring-shut``: a ring round the goal with such a gap;
* ``weak-wall``: a wall of threats of weight 0.05-0.2, spaced 1.2-2.8 sigma.

Trap threats are spaced at 1.1-1.5 of their spread, so their cores (radius
1.18 spreads) overlap and the only ways round are at the ends; they get
random facings with small skew (0-0.6) so the cores stay closed.  Distractors
(up to 20 threats in all, old kinds only) are kept clear of the start and goal.

Ground truth (``reachability``) does not ask the planner: it rasterises the
threat cores (``Cores.raster``, the same rule as every check) on a grid of at
most a twelfth of the narrowest standard deviation and asks whether start and
goal share a 4-connected free component.  It does so at the core fractions
0.48, 0.5 and 0.52; a case whose answer changes across that band is
*ambiguous* and is left out of the reach and honesty rates.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # the compiled core is imported where used: `pfp bench`'s parser imports this suite
    from pfp_service.core.threat import Threat
    from pfp_service.core.zones import Zone

__all__ = ["KINDS", "Case", "Verdict", "generate", "reachability"]

KINDS = (
    "open",
    "horseshoe",
    "cup",
    "wall",
    "block",
    "open",
    "enclosure-start",
    "enclosure-goal",
    "corridor",
    "nested",
    "s-bend",
    "shadow",
    "clutter",
    "anisotropic",
    "gap-open",
    "gap-shut",
    "ring-open",
    "ring-shut",
    "weak-wall",
)
_BOUNDED = ("s-bend",)
_OLD = KINDS[:8]
# x, y, facing, sigma_r, sigma_l, skew (unit frame); optional weight
_Spec = tuple[float, ...]
Bounds = tuple[tuple[float, float], tuple[float, float]]


@dataclass(frozen=True, slots=True)
class Case:
    """One generated scenario."""

    name: str
    kind: str
    start: tuple[float, float]
    goal: tuple[float, float]
    threats: tuple[Threat, ...]
    scale_m: float
    bounds: Bounds | None = None
    zones: tuple[Zone, ...] = ()  # keep-out zones (``bench._zone_cases``)

    @property
    def enclosed(self) -> bool:
        """What the generator meant: no way avoids every core (``reachability`` decides)."""
        return self.kind.startswith(("enclosure", "zone-enclosure")) or self.kind == "ring-shut"


def _trap(rng: np.random.Generator, pts: list[tuple[float, float]], sigma: float) -> list[_Spec]:
    return [
        (x, y, rng.uniform(0, 360), sigma, sigma * rng.uniform(0.85, 1.0), rng.uniform(0, 0.6))
        for x, y in pts
    ]


def _line(a: tuple[float, float], b: tuple[float, float], spacing: float) -> list[tuple[float, float]]:
    n = max(2, math.ceil(math.hypot(b[0] - a[0], b[1] - a[1]) / spacing) + 1)
    return [(a[0] + (b[0] - a[0]) * k / (n - 1), a[1] + (b[1] - a[1]) * k / (n - 1)) for k in range(n)]


def _structure(kind: str, rng: np.random.Generator) -> list[_Spec]:
    s = rng.uniform(0.03, 0.045)
    gap = s * rng.uniform(1.1, 1.4)
    if kind == "horseshoe":
        r, cx = rng.uniform(0.1, 0.16), rng.uniform(0.45, 0.6)
        n = max(5, math.ceil(r * math.radians(250) / gap))
        angles = np.radians(np.linspace(-125, 125, n))
        return _trap(rng, [(cx + r * math.cos(a), r * math.sin(a)) for a in angles], s)
    if kind == "cup":
        w, d, bx = rng.uniform(0.1, 0.16), rng.uniform(0.08, 0.15), rng.uniform(0.55, 0.7)
        pts = _line((bx, -w), (bx, w), gap) + _line((bx - d, w), (bx, w), gap)[:-1]
        pts += _line((bx - d, -w), (bx, -w), gap)[:-1]
        return _trap(rng, pts, s)
    if kind == "wall":
        h, wx = rng.uniform(0.12, 0.25), rng.uniform(0.4, 0.6)
        return _trap(rng, _line((wx, -h), (wx, h), gap), s)
    if kind == "block":
        big = rng.uniform(0.06, 0.1)
        bx = rng.uniform(0.4, 0.6)
        if rng.random() < 0.5:
            return [(bx, 0.0, 270.0, big, big, 0.0)]
        return [(bx, y, 270.0, big, big * 0.8, 0.0) for y in (-0.7 * big, 0.7 * big)]
    if kind.startswith("enclosure"):
        cx = 0.0 if kind == "enclosure-start" else 1.0
        r = rng.uniform(0.1, 0.15)
        n = math.ceil(2 * math.pi * r / gap)
        a = 2 * math.pi * np.arange(n) / n + rng.uniform(0, 2 * math.pi)
        return _trap(rng, [(cx + r * math.cos(t), r * math.sin(t)) for t in a], s)
    return _new_structure(kind, rng, s, gap)


def _gap_half(sigma: float, ratio: float) -> float:
    """Half the spacing of two unskewed round threats whose own levels at the middle are ``ratio`` of peak."""
    return sigma * math.sqrt(-2.0 * math.log(ratio))


def _new_structure(kind: str, rng: np.random.Generator, s: float, gap: float) -> list[_Spec]:
    if kind == "corridor":
        c, sk = rng.uniform(1.4, 2.2) * s, rng.uniform(2.0, 5.0)
        pts = _line((0.2, 0.0), (0.8, 0.0), gap)
        lines: list[_Spec] = [(x, c, 180.0, s, s, sk) for x, _ in pts]
        return lines + [(x, -c, 0.0, s, s, sk) for x, _ in pts]
    if kind == "nested":
        out: list[_Spec] = []
        for bx, w in ((rng.uniform(0.3, 0.4), rng.uniform(0.08, 0.11)), (rng.uniform(0.7, 0.8), 0.16)):
            d = rng.uniform(0.06, 0.1)
            pts = _line((bx, -w), (bx, w), gap) + _line((bx - d, w), (bx, w), gap)[:-1]
            pts += _line((bx - d, -w), (bx, -w), gap)[:-1]
            out += _trap(rng, pts, s)
        return out
    if kind == "s-bend":  # bounds |y| <= 0.25; walls run past them so no gap hides at an edge
        w1, w2 = rng.uniform(0.3, 0.4), rng.uniform(0.6, 0.7)
        return _trap(rng, _line((w1, -0.4), (w1, 0.08), gap) + _line((w2, -0.08), (w2, 0.4), gap), s)
    if kind == "shadow":
        sr = rng.uniform(0.05, 0.08)
        out = [
            (
                1.0 - rng.uniform(2.0, 3.0) * sr,
                rng.uniform(-0.3, 0.3) * sr,
                270.0,
                sr,
                sr * 0.9,
                rng.uniform(5, 15),
            )
        ]
        return out + [(rng.uniform(0.3, 0.7), rng.uniform(-0.2, 0.2), rng.uniform(0, 360), 0.04, 0.03, 1.0)]
    if kind == "clutter":
        n = int(rng.integers(200, 1001))
        out = []
        while len(out) < n:
            x, y = rng.uniform(0.05, 0.95), rng.uniform(-0.45, 0.45)
            sr = rng.uniform(0.004, 0.012)
            if math.hypot(x, y) < 6 * sr or math.hypot(x - 1, y) < 6 * sr:
                continue
            out.append((x, y, rng.uniform(0, 360), sr, sr * rng.uniform(0.4, 1.0), rng.uniform(0, 3)))
        return out
    if kind == "anisotropic":
        if rng.random() < 0.5:  # a wedge of needles, open towards the start
            sr, half = rng.uniform(0.05, 0.08), rng.uniform(25, 40)
            tip = rng.uniform(0.55, 0.7)
            out = []
            for side in (1.0, -1.0):
                a = math.radians(180.0 - side * half)  # from the tip back towards the start
                for k in range(4):
                    d = (k + 0.5) * 1.6 * sr
                    x, y = tip + d * math.cos(a), d * math.sin(a)
                    facing = (90.0 - math.degrees(a)) % 360  # compass bearing along the arm
                    out.append((x, y, facing, sr, sr * 0.05, rng.uniform(10, 50)))
            return out
        out = []
        for k, x in enumerate((0.3, 0.5, 0.7)):  # pancakes: thin along the line, wide across it
            sr = rng.uniform(0.006, 0.012)
            y = (0.06 if k % 2 else -0.06) * rng.uniform(0.5, 1.5)
            out.append((x, y, 270.0, sr, sr * rng.uniform(8, 20), rng.uniform(10, 50)))
        return out
    if kind in ("gap-open", "gap-shut"):
        ratio = rng.uniform(0.35, 0.45) if kind == "gap-open" else rng.uniform(0.55, 0.65)
        g, wx, h = _gap_half(s, ratio), rng.uniform(0.4, 0.6), 0.9
        yc = rng.uniform(-0.05, 0.05)
        pts = _line((wx, yc + g), (wx, h), 1.2 * s) + _line((wx, yc - g), (wx, -h), 1.2 * s)
        return [(x, y, 270.0, s, s, 0.0) for x, y in pts]
    if kind in ("ring-open", "ring-shut"):
        ratio = rng.uniform(0.35, 0.45) if kind == "ring-open" else rng.uniform(0.55, 0.65)
        r = rng.uniform(0.12, 0.16)
        half = math.asin(min(1.0, _gap_half(s, ratio) / r))  # the gap faces the start
        n = max(3, math.ceil((2 * math.pi - 2 * half) * r / (1.2 * s)))
        arc = math.pi + half + (2 * math.pi - 2 * half) * np.arange(n) / (n - 1)
        return [(1.0 + r * math.cos(t), r * math.sin(t), 0.0, s, s, 0.0) for t in arc.tolist()]
    if kind == "weak-wall":
        h, wx, sp = rng.uniform(0.12, 0.25), rng.uniform(0.4, 0.6), rng.uniform(1.2, 2.8)
        return [(x, y, 270.0, s, s, 0.0, rng.uniform(0.05, 0.2)) for x, y in _line((wx, -h), (wx, h), sp * s)]
    return []


def _distractors(rng: np.random.Generator, n: int, keep_clear: list[_Spec]) -> list[_Spec]:
    out: list[_Spec] = []
    tries = 0
    while len(out) < n and tries < 500:
        tries += 1
        x, y = rng.uniform(0.1, 0.9), rng.uniform(-0.35, 0.35)
        sr = rng.uniform(0.025, 0.07)
        if math.hypot(x, y) < 5 * sr or math.hypot(x - 1, y) < 5 * sr:
            continue
        if any(math.hypot(x - t[0], y - t[1]) < 3 * (sr + t[3]) for t in keep_clear + out):
            continue
        out.append((x, y, rng.uniform(0, 360), sr, sr * rng.uniform(0.5, 1.0), rng.uniform(0, 3)))
    return out


def generate(count: int, seed: int) -> list[Case]:
    """``count`` scenarios from ``seed``; the same arguments always give the same suite."""
    from pfp_service.core.cores import Cores
    from pfp_service.core.threat import Threat, ThreatField

    rng = np.random.default_rng(seed)
    cases = []
    for i in range(count):
        kind = KINDS[i % len(KINDS)]
        trap = _structure(kind, rng)
        room = max(0, 20 - len(trap))
        lo = 2 if kind == "open" else 0
        n_extra = int(rng.integers(lo, min(room, 12 if kind != "open" else 20) + 1)) if room >= lo else 0
        specs = trap + (_distractors(rng, n_extra, trap) if kind in _OLD else [])
        if len(specs) < 2:  # every scenario has at least 2 threats
            specs += _distractors(rng, 2 - len(specs), specs)
        lo_m, hi_m = (10_000.0, 30_000.0) if kind == "clutter" else (10.0, 30_000.0)
        scale = float(math.exp(rng.uniform(math.log(lo_m), math.log(hi_m))))
        phi = rng.uniform(0, 2 * math.pi)
        if kind in _BOUNDED:
            phi = 0.5 * math.pi * int(rng.integers(0, 4))
        c, s = math.cos(phi), math.sin(phi)
        ox, oy = rng.uniform(-5, 5) * scale, rng.uniform(-5, 5) * scale

        def place(
            x: float, y: float, c: float = c, s: float = s, ox: float = ox, oy: float = oy
        ) -> tuple[float, float]:
            return (ox + scale * (c * x - s * y), oy + scale * (s * x + c * y))

        threats = tuple(
            Threat.from_facing(
                place(sp[0], sp[1]),
                (sp[2] - math.degrees(phi)) % 360,
                scale * sp[3],
                scale * sp[4],
                sp[5],
                sp[6] if len(sp) > 6 else rng.uniform(0.5, 1.5),
                f"t{j + 1}",
            )
            for j, sp in enumerate(specs)
        )
        start, goal = place(0.0, 0.0), place(1.0, 0.0)
        bounds = None
        if kind in _BOUNDED:
            a, b = place(-0.1, -0.25), place(1.1, 0.25)
            bounds = ((min(a[0], b[0]), min(a[1], b[1])), (max(a[0], b[0]), max(a[1], b[1])))
        if Cores(ThreatField(threats)).inside(np.array([start, goal])).any():
            threats = tuple(
                t for t in threats if not Cores(ThreatField([t])).inside(np.array([start, goal])).any()
            )
        cases.append(Case(f"q{i:02d}-{kind}", kind, start, goal, threats, scale, bounds))
    return cases


@dataclass(frozen=True, slots=True)
class Verdict:
    """Ground truth for one case: ``reachable`` is ``None`` when the core band makes it ambiguous."""

    reachable: bool | None
    cell_m: float
    by_fraction: tuple[bool, ...]


FRACTIONS = (0.48, 0.5, 0.52)
_MAX_NODES = 16_000_000


def reachability(case: Case, fractions: tuple[float, ...] = FRACTIONS) -> Verdict:
    """Is there a way from start to goal that enters no core, by a raster of the cores (not the planner)?"""
    from scipy import ndimage

    from pfp_service.core.cores import Cores
    from pfp_service.core.threat import ThreatField

    (sx, sy), (gx, gy) = case.start, case.goal
    d0 = math.hypot(gx - sx, gy - sy)
    if case.bounds is not None:
        (x0, y0), (x1, y1) = case.bounds
    else:
        x0, y0, x1, y1 = min(sx, gx) - d0, min(sy, gy) - d0, max(sx, gx) + d0, max(sy, gy) + d0
    field = ThreatField(case.threats)
    s_min = min((t.min_sigma() for t in case.threats if t.weight > 0), default=d0)
    h = max(s_min / 12.0, math.sqrt((x1 - x0) * (y1 - y0) / _MAX_NODES))
    shape = (math.ceil((x1 - x0) / h) + 1, math.ceil((y1 - y0) / h) + 1)
    answers = []
    for f in fractions:
        free = ~Cores(field, f).raster((x0, y0), h, shape)
        labels, _ = ndimage.label(free)  # 4-connected: never through a diagonal pinch
        a, b = (
            _component(labels, (sx - x0) / h, (sy - y0) / h),
            _component(labels, (gx - x0) / h, (gy - y0) / h),
        )
        answers.append(bool(a & b))
    verdict = answers[0] if len(set(answers)) == 1 else None
    return Verdict(verdict, h, tuple(answers))


def _component(labels: np.ndarray, fi: float, fk: float) -> set[int]:
    """Labels of the free nodes at the corners of the cell holding a point."""
    i, k = math.floor(fi), math.floor(fk)
    out = set()
    for di in (0, 1):
        for dk in (0, 1):
            ii, kk = min(max(i + di, 0), labels.shape[0] - 1), min(max(k + dk, 0), labels.shape[1] - 1)
            if labels[ii, kk]:
                out.add(int(labels[ii, kk]))
    return out
