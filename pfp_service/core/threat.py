"""The threat model: the paper's multivariate skew-normal, and a compiled field of many.

A single threat is ``t(x) = 2 phi2(x - xi; Omega) Phi(alpha^T omega^-1 (x - xi))``
(Azzalini and Dalla Valle 1996).  Users give it as a position, a compass facing
and two spreads; the mapping to ``(xi, Omega, alpha)`` is fixed so that results
compare across tools:

    d = (sin b, cos b),  R = [d, d_perp],  Omega = R diag(sr^2, sl^2) R^T,
    omega = sqrt(diag Omega),  alpha = k omega d / sr   (so omega^-1 alpha = k d / sr)

``ThreatField`` packs any number of threats into one array and evaluates the
weighted sum and its exact gradient at one point or many, through ``kernels``.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Container, Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq
from scipy.special import ndtr

from pfp_service.core import kernels
from pfp_service.core.options import Intensity
from pfp_service.core.visibility import AtHeight, Sight, at_height, concat, reach_box, stack_rows, widen
from pfp_service.core.zones import ZoneSet

__all__ = ["LEVEL_FLOOR", "PACKED_COLUMNS", "Intensity", "Threat", "ThreatField", "skew_normal_mode"]

# One row of ``ThreatField.packed`` per threat, in the kernels' column order.
PACKED_COLUMNS = kernels.PACKED_COLUMNS
# Of the strongest threat's peak: the terms ``level_culled`` and the route grids leave out.
LEVEL_FLOOR = 1e-9


_NO_ZONES = ZoneSet()


@functools.lru_cache(maxsize=1 << 16)
def skew_normal_mode(q: float) -> float:
    """Mode of the standard univariate skew-normal with shape ``q >= 0``.

    Solves ``q phi(q v) = v Phi(q v)``; the root lies in ``[0, 2)``.  Memoised:
    a field, its cores and its previews ask for the same threats' modes again.
    """
    if q <= 0.0:
        return 0.0

    def eq(v: float) -> float:
        return q * math.exp(-0.5 * (q * v) ** 2) / math.sqrt(2 * math.pi) - v * float(ndtr(q * v))

    return float(brentq(eq, 0.0, 2.0, xtol=1e-14, rtol=1e-14))


@dataclass(frozen=True, slots=True)
class Threat:
    """One enemy threat in raw skew-normal form.

    Attributes:
        xi: location (the enemy position), metres ``(x east, y north)``.
        omega: 2x2 symmetric positive-definite scale matrix, square metres.
        alpha: Azzalini's shape vector (dimensionless).
        weight: multiplier ``w_j >= 0``; its meaning depends on the intensity scale.
        id: the threat's name, for reports.
        observer_height_m: its eye above the ground, for line of sight over terrain
            (``core.visibility``); without terrain it changes nothing.
    """

    xi: tuple[float, float]
    omega: tuple[tuple[float, float], tuple[float, float]]
    alpha: tuple[float, float]
    weight: float = 1.0
    id: str = ""
    observer_height_m: float = 2.0

    def __post_init__(self) -> None:
        """Refuse a threat the field could not evaluate, here rather than as a ZeroDivisionError later.

        Raises:
            ValueError: a non-finite number, a negative weight, or an ``omega``
                that is not symmetric positive definite once computed in floats
                (e.g. a spread so small its square underflows).
        """
        (o00, o01), (o10, o11) = self.omega
        numbers = (*self.xi, o00, o01, o10, o11, *self.alpha, self.weight, self.observer_height_m)
        if not all(math.isfinite(v) for v in numbers):
            raise ValueError(
                f"threat {self.id!r}: position, omega, alpha, weight and observer height must be finite"
            )
        if not self.weight >= 0.0:
            raise ValueError(f"threat {self.id!r}: weight must be >= 0, got {self.weight!r}")
        if abs(o01 - o10) > 1e-9 * math.sqrt(abs(o00 * o11)):  # rounding of R D R^T is allowed
            raise ValueError(f"threat {self.id!r}: omega must be symmetric")
        det = o00 * o11 - o01 * o01
        if not (o00 > 0.0 and o11 > 0.0 and det > 0.0 and math.isfinite(det)):
            raise ValueError(f"threat {self.id!r}: omega must be positive definite (det = {det:g})")
        if not all(math.isfinite(v) for v in (o11 / det, o00 / det, 1.0 / math.sqrt(det))):
            raise ValueError(f"threat {self.id!r}: omega is too nearly singular to invert")

    @classmethod
    def from_facing(
        cls,
        position: Sequence[float],
        facing_deg: float,
        sigma_range: float,
        sigma_lateral: float,
        skew: float,
        weight: float = 1.0,
        id: str = "",
        observer_height_m: float = 2.0,
    ) -> Threat:
        """Build a threat from the user-facing parameters (see module docstring)."""
        b = math.radians(facing_deg)
        dx, dy = math.sin(b), math.cos(b)
        px, py = dy, -dx  # d rotated a quarter turn clockwise; only d_perp d_perp^T matters
        sr2, sl2 = sigma_range**2, sigma_lateral**2
        o00 = sr2 * dx * dx + sl2 * px * px
        o01 = sr2 * dx * dy + sl2 * px * py
        o11 = sr2 * dy * dy + sl2 * py * py
        w0, w1 = math.sqrt(o00), math.sqrt(o11)
        alpha = (skew * w0 * dx / sigma_range, skew * w1 * dy / sigma_range)
        return cls(
            xi=(float(position[0]), float(position[1])),
            omega=((o00, o01), (o01, o11)),
            alpha=alpha,
            weight=float(weight),
            id=id,
            observer_height_m=float(observer_height_m),
        )

    # -- derived quantities -------------------------------------------------
    def precision(self) -> tuple[float, float, float]:
        """``P = Omega^-1`` as ``(P00, P01, P11)``."""
        (o00, o01), (_, o11) = self.omega
        det = o00 * o11 - o01 * o01
        return o11 / det, -o01 / det, o00 / det

    def shape(self) -> tuple[float, float]:
        """``a = omega^-1 alpha``: the skew direction scaled per unit length."""
        (o00, _), (_, o11) = self.omega
        return self.alpha[0] / math.sqrt(o00), self.alpha[1] / math.sqrt(o11)

    def density_scale(self) -> float:
        """``2 / (2 pi sqrt(det Omega))``: the density's leading constant."""
        (o00, o01), (_, o11) = self.omega
        return 2.0 / (2.0 * math.pi * math.sqrt(o00 * o11 - o01 * o01))

    def mode(self) -> tuple[float, float]:
        """Where the density peaks, in metres: the one place a threat's mode is computed.

        Setting the gradient to zero gives ``x* = xi + Omega a v / q`` with
        ``q = sqrt(a^T Omega a)`` and ``v`` the mode of the univariate
        skew-normal of shape ``q``; an unskewed threat peaks at ``xi``.
        The map, GeoJSON and ``peak_density`` all ask here.
        """
        (o00, o01), (_, o11) = self.omega
        ax, ay = self.shape()
        oax, oay = o00 * ax + o01 * ay, o01 * ax + o11 * ay
        q = math.sqrt(max(ax * oax + ay * oay, 0.0))
        if q == 0.0:
            return self.xi
        v = skew_normal_mode(q)
        return self.xi[0] + oax * v / q, self.xi[1] + oay * v / q

    def peak_density(self) -> float:
        """Maximum of the unweighted density: its value at ``mode()``."""
        ax, ay = self.shape()
        mx, my = self.mode()
        zx, zy = mx - self.xi[0], my - self.xi[1]
        if zx == 0.0 and zy == 0.0:
            return self.density_scale() * 0.5
        p00, p01, p11 = self.precision()
        quad = p00 * zx * zx + 2 * p01 * zx * zy + p11 * zy * zy
        return self.density_scale() * math.exp(-0.5 * quad) * float(ndtr(ax * zx + ay * zy))

    def spread(self) -> float:
        """Geometric-mean spread ``det(Omega)^(1/4)`` in metres."""
        (o00, o01), (_, o11) = self.omega
        return float((o00 * o11 - o01 * o01) ** 0.25)

    def min_sigma(self) -> float:
        """Narrowest standard deviation ``sqrt(lambda_min(Omega))`` in metres: the finest scale to resolve."""
        (o00, o01), (_, o11) = self.omega
        half_trace = 0.5 * (o00 + o11)
        lam_min = half_trace - math.sqrt(max(half_trace**2 - (o00 * o11 - o01 * o01), 0.0))
        if lam_min <= 0.0:  # rounding on an extreme aspect ratio: fall back on det / lambda_max
            lam_min = (o00 * o11 - o01 * o01) / (
                half_trace + math.sqrt(max(half_trace**2 - (o00 * o11 - o01 * o01), 0.0))
            )
        return math.sqrt(lam_min)

    def max_sigma(self) -> float:
        """Widest standard deviation ``sqrt(lambda_max(Omega))`` in metres: how far the threat reaches."""
        (o00, o01), (_, o11) = self.omega
        half_trace = 0.5 * (o00 + o11)
        return math.sqrt(half_trace + math.sqrt(max(half_trace**2 - (o00 * o11 - o01 * o01), 0.0)))

    def translated(self, dx: float, dy: float) -> Threat:
        return Threat(
            (self.xi[0] + dx, self.xi[1] + dy),
            self.omega,
            self.alpha,
            self.weight,
            self.id,
            self.observer_height_m,
        )


class ThreatField:
    """A set of threats packed for fast evaluation of ``sum_j w_j t_j``.

    Immutable: adding or removing a threat builds a new field (cheap).
    The field also carries the keep-out zones in force (``zones``, a
    ``core.zones.ZoneSet``; empty by default), so everything that takes a
    field sees them: ``with_zones`` gives the same threats with other zones.
    With a ``sight`` (``core.visibility``), each threat's row carries its
    window of lowest visible heights and every kernel masks it by line of
    sight; the fields derived from this one keep the same sight.
    """

    __slots__ = ("__weakref__", "_reach", "intensity", "packed", "positions", "sight", "threats", "zones")

    def __init__(
        self,
        threats: Iterable[Threat] = (),
        intensity: Intensity = "peak",
        zones: ZoneSet | None = None,
        sight: Sight | None = None,
    ) -> None:
        if intensity not in ("peak", "density"):
            raise ValueError(f"intensity: must be 'peak' or 'density', got {intensity!r}")
        self.threats: tuple[Threat, ...] = tuple(threats)
        self.intensity: Intensity = intensity
        packed = np.zeros((len(self.threats), len(PACKED_COLUMNS)))
        for j, t in enumerate(self.threats):
            scale = t.density_scale()
            if intensity == "peak":
                scale = scale * t.weight / t.peak_density()
            else:
                scale = scale * t.weight
            packed[j] = kernels.pack_row(t.xi, t.precision(), t.shape(), scale)
        if sight is not None and len(self.threats):
            packed = widen(packed, [sight(t, reach_box(packed[j])) for j, t in enumerate(self.threats)])
        self.sight = sight
        self.packed = packed
        self.positions = packed[:, [kernels.XI_X, kernels.XI_Y]].copy()
        self._reach: np.ndarray | None = None
        self.zones: ZoneSet = zones if zones is not None else _NO_ZONES

    @classmethod
    def from_rows(
        cls, threats: Sequence[Threat], rows: Sequence[np.ndarray], intensity: Intensity = "peak"
    ) -> ThreatField:
        """The field of ``threats`` from rows packed before (``rows[j]``: a ``packed`` row of ``threats[j]``).

        The live world keeps each threat's row while it stands: a threat put
        among a hundred packs one row, not a hundred.
        """
        out = cls.__new__(cls)
        out.threats = tuple(threats)
        out.intensity = intensity
        out.packed = stack_rows([np.asarray(r, dtype=np.float64) for r in rows])
        out.positions = out.packed[:, [kernels.XI_X, kernels.XI_Y]].copy()
        out._reach = None
        out.zones = _NO_ZONES
        out.sight = None
        return out

    def __len__(self) -> int:
        return len(self.threats)

    def with_threats(self, threats: Iterable[Threat]) -> ThreatField:
        return ThreatField(threats, self.intensity, self.zones, self.sight)

    def with_zones(self, zones: ZoneSet) -> ThreatField:
        """These threats (their packed rows reused) with ``zones`` in force instead."""
        out = ThreatField.__new__(ThreatField)
        out.threats = self.threats
        out.intensity = self.intensity
        out.packed = self.packed
        out.positions = self.positions
        out._reach = self._reach
        out.zones = zones
        out.sight = self.sight
        return out

    def seen_at(self, height_m: float) -> ThreatField:
        """These threats and zones, each threat seeing a unit ``height_m`` tall: its window's heights kept
        (``visibility.at_height``), its sight's windows at that height for the threats added (``plus``)."""
        out = self.with_zones(self.zones)
        out.packed = at_height(self.packed, height_m)
        inner = self.sight.sight if isinstance(self.sight, AtHeight) else self.sight
        out.sight = AtHeight(inner, height_m) if inner is not None else None
        return out

    def plus(self, extra: Iterable[Threat], replacing: Container[str] = ()) -> ThreatField:
        """This field without the threats whose id is in ``replacing``, with ``extra`` after them.

        The rows already packed are reused, not packed again: a what-if on a
        field of thousands of threats costs its own threats only.
        """
        added = ThreatField(extra, self.intensity, sight=self.sight)
        keep = [j for j, t in enumerate(self.threats) if t.id not in replacing]
        out = ThreatField.__new__(ThreatField)
        out.threats = tuple(self.threats[j] for j in keep) + added.threats
        out.intensity = self.intensity
        out.packed = concat(self.packed[keep], added.packed)
        out.positions = out.packed[:, [kernels.XI_X, kernels.XI_Y]].copy()
        out._reach = None
        out.zones = self.zones
        out.sight = self.sight
        return out

    # -- evaluation ---------------------------------------------------------
    def level_grad_at(self, x: float, y: float) -> tuple[float, float, float]:
        """``(level, d/dx, d/dy)`` at one point."""
        return kernels.point_level_grad(self.packed, x, y)

    def level_grad(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Level ``(N,)`` and gradient ``(N, 2)`` at ``points`` of shape ``(N, 2)``."""
        pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
        out = np.empty((pts.shape[0], 3))
        kernels.batch_level_grad(self.packed, pts, out)
        return out[:, 0], out[:, 1:]

    def level(self, points: np.ndarray) -> np.ndarray:
        """Level at ``points`` of shape ``(..., 2)``, returned with shape ``(...)``."""
        arr = np.asarray(points, dtype=np.float64)
        pts = np.ascontiguousarray(arr.reshape(-1, 2))
        out = np.empty(pts.shape[0])
        kernels.batch_level(self.packed, pts, out)
        return out.reshape(arr.shape[:-1])

    def level_culled(self, points: np.ndarray) -> np.ndarray:
        """``level(points)`` without the terms below ``LEVEL_FLOOR`` of the strongest peak.

        For searches and estimates among many threats: the points are cut into
        tiles and each tile is summed over only the threats whose
        ``LEVEL_FLOOR`` box meets it.  Metrics and the stepper use ``level``.
        """
        arr = np.asarray(points, dtype=np.float64)
        pts = np.ascontiguousarray(arr.reshape(-1, 2))
        out = np.zeros(len(pts))
        if not len(self.threats) or not len(pts):
            return out.reshape(arr.shape[:-1])
        reach = self._reach if self._reach is not None else self._reach_boxes()
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        tiles = min(8, max(1, int(math.sqrt(len(pts) * len(self.threats) / 200_000.0))))
        size = np.maximum((hi - lo) / tiles, 1e-300)
        tile = np.minimum(((pts - lo) / size).astype(np.int64), tiles - 1)
        key = tile[:, 0] * tiles + tile[:, 1]
        order = np.argsort(key, kind="stable")
        cuts = np.searchsorted(key[order], np.arange(tiles * tiles + 1))
        for t in range(tiles * tiles):
            rows = order[cuts[t] : cuts[t + 1]]
            if not len(rows):
                continue
            sub = pts[rows]
            tlo, thi = sub.min(axis=0), sub.max(axis=0)
            near = (
                (reach[:, 0] <= thi[0])
                & (reach[:, 2] >= tlo[0])
                & (reach[:, 1] <= thi[1])
                & (reach[:, 3] >= tlo[1])
            )
            if near.any():
                vals = np.empty(len(rows))
                kernels.batch_level(np.ascontiguousarray(self.packed[near]), np.ascontiguousarray(sub), vals)
                out[rows] = vals
        return out.reshape(arr.shape[:-1])

    def _reach_boxes(self) -> np.ndarray:
        """Per threat, the box ``(x0, y0, x1, y1)`` outside which its term is below the floor."""
        packed = self.packed
        scale = packed[:, kernels.SCALE]
        floor = LEVEL_FLOOR * float(scale.max())
        qmax = np.where(scale > floor, 2.0 * np.log(np.maximum(scale, floor) / max(floor, 1e-300)), 0.0)
        qmax = np.minimum(qmax, kernels.Q_CUTOFF)
        det = packed[:, kernels.P00] * packed[:, kernels.P11] - packed[:, kernels.P01] ** 2
        ex = np.sqrt(qmax * packed[:, kernels.P11] / det)
        ey = np.sqrt(qmax * packed[:, kernels.P00] / det)
        cx, cy = packed[:, kernels.XI_X], packed[:, kernels.XI_Y]
        self._reach = np.stack([cx - ex, cy - ey, cx + ex, cy + ey], axis=1)
        return self._reach

    def clearance(self, points: np.ndarray) -> float:
        """Minimum Euclidean distance from any of ``points`` to any threat position."""
        if not len(self.threats):
            return math.inf
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        d = np.hypot(
            pts[:, None, 0] - self.positions[None, :, 0], pts[:, None, 1] - self.positions[None, :, 1]
        )
        return float(d.min())
