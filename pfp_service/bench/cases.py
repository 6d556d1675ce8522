"""The seeded scenario suite of ``pfp bench quality``: open fields and deliberate traps.

Every scenario is drawn in a unit frame (start at the origin, goal at
``(1, 0)``) and then scaled to a start-goal distance log-uniform in
10-30,000 m, rotated and shifted at random, so the suite exercises the
scale-free rule as well as the traps.  Kinds, in rotation:

* ``open``: 2-20 scattered threats, random facings and skews;
* ``horseshoe``: an arc of threats around the goal bearing, open towards the start;
* ``cup``: a U of three straight walls, open towards the start;
* ``wall``: a straight wall across the start-goal line, open at both ends;
* ``block``: one large unskewed threat (or a symmetric pair) square on the line;
* ``enclosure-start`` / ``enclosure-goal``: a closed ring round the start or
  the goal whose cores overlap, so no way avoids every core.

Trap threats are spaced at 1.1-1.5 of their spread, so their cores (radius
1.18 spreads) overlap and the only ways round are at the ends; they get
random facings with small skew (0-0.6) so the cores stay closed.  Distractors
(up to 20 threats in all) are kept clear of the start and goal.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pfp_service.core.cores import Cores
from pfp_service.core.threat import Threat, ThreatField

__all__ = ["KINDS", "Case", "generate"]

KINDS = ("open", "horseshoe", "cup", "wall", "block", "open", "enclosure-start", "enclosure-goal")
_Spec = tuple[float, float, float, float, float, float]  # x, y, facing, sigma_r, sigma_l, skew (unit frame)


@dataclass(frozen=True, slots=True)
class Case:
    """One generated scenario."""

    name: str
    kind: str
    start: tuple[float, float]
    goal: tuple[float, float]
    threats: tuple[Threat, ...]
    scale_m: float

    @property
    def enclosed(self) -> bool:
        return self.kind.startswith("enclosure")


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
    rng = np.random.default_rng(seed)
    cases = []
    for i in range(count):
        kind = KINDS[i % len(KINDS)]
        trap = _structure(kind, rng)
        room = max(0, 20 - len(trap))
        lo = 2 if kind == "open" else 0
        n_extra = int(rng.integers(lo, min(room, 12 if kind != "open" else 20) + 1)) if room >= lo else 0
        specs = trap + _distractors(rng, n_extra, trap)
        if len(specs) < 2:  # every scenario has 2-20 threats
            specs += _distractors(rng, 2 - len(specs), specs)
        scale = float(math.exp(rng.uniform(math.log(10.0), math.log(30_000.0))))
        phi = rng.uniform(0, 2 * math.pi)
        c, s = math.cos(phi), math.sin(phi)
        ox, oy = rng.uniform(-5, 5) * scale, rng.uniform(-5, 5) * scale

        def place(
            x: float, y: float, c: float = c, s: float = s, ox: float = ox, oy: float = oy
        ) -> tuple[float, float]:
            return (ox + scale * (c * x - s * y), oy + scale * (s * x + c * y))

        threats = tuple(
            Threat.from_facing(
                place(x, y),
                (f - math.degrees(phi)) % 360,
                scale * sr,
                scale * sl,
                k,
                rng.uniform(0.5, 1.5),
                f"t{j + 1}",
            )
            for j, (x, y, f, sr, sl, k) in enumerate(specs)
        )
        start, goal = place(0.0, 0.0), place(1.0, 0.0)
        if Cores(ThreatField(threats)).inside(np.array([start, goal])).any():
            threats = tuple(
                t for t in threats if not Cores(ThreatField([t])).inside(np.array([start, goal])).any()
            )
        cases.append(Case(f"q{i:02d}-{kind}", kind, start, goal, threats, scale))
    return cases
