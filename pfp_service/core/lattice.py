"""The field's lattice for A*: levels at half a cell and cores at a quarter cell, filled tile by tile and kept.

``astar.lazy_route`` searches a ``grid.GridGraph``-shaped graph without
building it: what it reads is filled here the first time a search reads it,
``TILE`` lattice points a side at once, by the rasters' own rules
(``kernels.raster_level``, the cores' ``_raster``), and kept per field and
rung (``KEPT`` lattices, at most ``MAX_POINTS`` levels each), so the
searches under one field share them.  A value depends only on its lattice
index, never on what was filled before, so a preview and the live unit find
the same route.  A lattice's point ``(i, k)`` lies at ``origin + (i, k) h``:
the kept ones at the plane's origin, so searches over different boxes share
them; a search with keep-out zones uses its own, on the grid's very nodes.
"""

from __future__ import annotations

import math
import weakref
from collections import OrderedDict

import numba
import numpy as np

from pfp_service.core import kernels
from pfp_service.core.cores import Cores
from pfp_service.core.threat import ThreatField

__all__ = [
    "LADDER",
    "TILE",
    "Lattice",
    "cell_ladder",
    "clear_lattices",
    "fill_cores",
    "fill_level",
    "kept_lattice",
]

TILE = 16  # lattice points a side of a tile computed at once
LADDER = 8  # a lone search's cell is 2 ** (k / LADDER) m, so the searches under one field share lattices


@numba.njit(cache=True, nogil=True)
def _spans(  # type: ignore[no-untyped-def]
    packed: np.ndarray, h: float, floor: float, q_cap: float, ox: float, oy: float
):
    """Per threat, the lattice box ``(i0, i1, k0, k1)`` its raster visits (unclamped) and whether it counts.

    Exactly the box ``kernels.raster_level`` (``q_cap = Q_CUTOFF``) and the
    cores' ``_raster`` (``q_cap = inf``) compute, before clamping to the lattice.
    """
    m = packed.shape[0]
    box = np.zeros((m, 4), dtype=np.int64)
    use = np.zeros(m, dtype=np.bool_)
    for j in range(m):
        s = packed[j, kernels.SCALE]
        if packed[j, kernels.ACTIVE] == 0.0 or s < floor:
            continue
        qmax = min(2.0 * math.log(s / floor), q_cap)
        p00, p01, p11 = packed[j, kernels.P00], packed[j, kernels.P01], packed[j, kernels.P11]
        det = p00 * p11 - p01 * p01
        ex = math.sqrt(qmax * p11 / det) + h
        ey = math.sqrt(qmax * p00 / det) + h
        cx, cy = packed[j, kernels.XI_X], packed[j, kernels.XI_Y]
        box[j, 0] = math.floor((cx - ex - ox) / h)
        box[j, 1] = math.ceil((cx + ex - ox) / h)
        box[j, 2] = math.floor((cy - ey - oy) / h)
        box[j, 3] = math.ceil((cy + ey - oy) / h)
        use[j] = True
    return box, use


@numba.njit(cache=True, nogil=True)
def fill_level(
    packed: np.ndarray,
    box: np.ndarray,
    use: np.ndarray,
    h: float,
    ox: float,
    oy: float,
    floor: float,
    out: np.ndarray,
    base_i: int,
    base_k: int,
    ti: int,
    tk: int,
) -> None:
    """The levels of tile ``(ti, tk)`` of ``out``, as ``kernels.raster_level`` sums them (threat by threat).

    Summed apart and then stored, so two searches filling one tile at once
    (threads, the GIL released) store the same values rather than adding twice.
    """
    nx, ny = out.shape  # out[0, 0] is lattice point (base_i, base_k), at (base_i h, base_k h)
    a0, a1 = base_i + ti * TILE, base_i + min(nx - 1, ti * TILE + TILE - 1)
    b0, b1 = base_k + tk * TILE, base_k + min(ny - 1, tk * TILE + TILE - 1)
    tile = np.zeros((a1 - a0 + 1, b1 - b0 + 1))
    for j in range(packed.shape[0]):
        if not use[j]:
            continue
        i0, i1 = max(a0, box[j, 0]), min(a1, box[j, 1])
        k0, k1 = max(b0, box[j, 2]), min(b1, box[j, 3])
        for i in range(i0, i1 + 1):
            x = ox + i * h
            for k in range(k0, k1 + 1):
                tile[i - a0, k - b0] += kernels.threat_term(packed, j, x, oy + k * h, floor, False)[0]
    out[a0 - base_i : a1 - base_i + 1, b0 - base_k : b1 - base_k + 1] = tile


@numba.njit(cache=True, nogil=True)
def fill_cores(
    packed: np.ndarray,
    box: np.ndarray,
    use: np.ndarray,
    h: float,
    ox: float,
    oy: float,
    fraction: float,
    out: np.ndarray,
    base_i: int,
    base_k: int,
    ti: int,
    tk: int,
) -> None:
    """The core flags of tile ``(ti, tk)`` of ``out``, as the cores' ``_raster`` sets them."""
    nx, ny = out.shape  # out[0, 0] is lattice point (base_i, base_k), at (base_i h, base_k h)
    a0, a1 = base_i + ti * TILE, base_i + min(nx - 1, ti * TILE + TILE - 1)
    b0, b1 = base_k + tk * TILE, base_k + min(ny - 1, tk * TILE + TILE - 1)
    for j in range(packed.shape[0]):
        if not use[j]:
            continue
        i0, i1 = max(a0, box[j, 0]), min(a1, box[j, 1])
        k0, k1 = max(b0, box[j, 2]), min(b1, box[j, 3])
        for i in range(i0, i1 + 1):
            x = ox + i * h
            for k in range(k0, k1 + 1):
                if out[i - base_i, k - base_k]:
                    continue
                if kernels.threat_term(packed, j, x, oy + k * h, fraction, False)[0] >= fraction:
                    out[i - base_i, k - base_k] = True


class Lattice:
    """One field's levels at ``h / 2`` and cores at ``h / 4`` for one cell ``h``, filled on demand and kept.

    Element ``[0, 0]`` of each array is an absolute lattice point whose
    indices are multiples of ``TILE``, so tiles stay aligned as it grows.
    """

    __slots__ = (
        "bbase",
        "bdone",
        "blocked",
        "cbox",
        "cuse",
        "fbase",
        "fdone",
        "fine",
        "lbox",
        "luse",
        "origin",
    )

    def __init__(
        self,
        packed: np.ndarray,
        lfloor: float,
        cores: Cores,
        h: float,
        origin: tuple[float, float] = (0.0, 0.0),
    ) -> None:
        self.origin = origin  # lattice point (i, k) is at origin + (i, k) h
        self.lbox, self.luse = _spans(packed, 0.5 * h, lfloor, kernels.Q_CUTOFF, *origin)
        self.cbox, self.cuse = _spans(cores.packed, 0.25 * h, float(cores.fraction), math.inf, *origin)
        self.fine: np.ndarray = np.zeros((0, 0))
        self.fdone: np.ndarray = np.zeros((0, 0), dtype=np.bool_)
        self.blocked: np.ndarray = np.zeros((0, 0), dtype=np.bool_)
        self.bdone: np.ndarray = np.zeros((0, 0), dtype=np.bool_)
        self.fbase = self.bbase = (0, 0)

    def cover(self, gi0: int, gk0: int, nx: int, ny: int) -> bool:
        """Grow to hold nodes ``gi0 .. gi0 + nx - 1`` by ``gk0 .. gk0 + ny - 1``; ``False`` past ``_MAX_POINTS``."""
        for fine, scale in ((True, 2), (False, 4)):
            lat, done, base = (
                (self.fine, self.fdone, self.fbase) if fine else (self.blocked, self.bdone, self.bbase)
            )
            lo = (scale * gi0 // TILE * TILE, scale * gk0 // TILE * TILE)
            hi = (scale * (gi0 + nx - 1), scale * (gk0 + ny - 1))
            if lat.size:
                top = (base[0] + lat.shape[0] - 1, base[1] + lat.shape[1] - 1)
                if base[0] <= lo[0] and base[1] <= lo[1] and top[0] >= hi[0] and top[1] >= hi[1]:
                    continue
                lo = (min(lo[0], base[0]), min(lo[1], base[1]))
                hi = (max(hi[0], top[0]), max(hi[1], top[1]))
            shape = (-(-(hi[0] - lo[0] + 1) // TILE) * TILE, -(-(hi[1] - lo[1] + 1) // TILE) * TILE)
            if shape[0] * shape[1] > (1 if fine else 4) * _MAX_POINTS:
                return False
            grown = np.zeros(shape, dtype=lat.dtype)
            grown_done = np.zeros((shape[0] // TILE, shape[1] // TILE), dtype=np.bool_)
            if lat.size:
                oi, ok = base[0] - lo[0], base[1] - lo[1]
                grown[oi : oi + lat.shape[0], ok : ok + lat.shape[1]] = lat
                grown_done[
                    oi // TILE : oi // TILE + done.shape[0], ok // TILE : ok // TILE + done.shape[1]
                ] = done
            if fine:
                self.fine, self.fdone, self.fbase = grown, grown_done, lo
            else:
                self.blocked, self.bdone, self.bbase = grown, grown_done, lo
        return True

    @property
    def nbytes(self) -> int:
        """Memory held by the lattices."""
        return int(self.fine.nbytes + self.blocked.nbytes + self.fdone.nbytes + self.bdone.nbytes)


_MAX_POINTS = 1 << 18  # a kept lattice: at most this many levels (2 MB) and 4x as many core flags (1 MB)
_KEPT = 6  # lattices kept per process, the least recently used dropped first (a storm meets 4-5 rungs)
_LATTICES: OrderedDict[tuple[weakref.ref[ThreatField], float, int], Lattice] = OrderedDict()


def kept_lattice(
    field: ThreatField, cores: Cores, packed: np.ndarray, lfloor: float, k: int, h: float
) -> Lattice:
    """The kept lattice of ``field`` for rung ``k`` (cores are a function of the field and their fraction)."""
    for gone in [key for key in _LATTICES if key[0]() is None]:
        del _LATTICES[gone]
    key = (weakref.ref(field), float(cores.fraction), k)
    lat = _LATTICES.get(key)
    if lat is None:
        lat = _LATTICES[key] = Lattice(packed, lfloor, cores, h)
        while len(_LATTICES) > _KEPT:
            _LATTICES.popitem(last=False)
    _LATTICES.move_to_end(key)
    return lat


def clear_lattices() -> None:
    """Forget every kept lattice (a cold start, as a new worker has)."""
    _LATTICES.clear()


def cell_ladder(cell_m: float) -> tuple[int, float]:
    """The rung ``k`` and cell ``2 ** (k / LADDER)`` at or just under ``cell_m`` (at most 9 % finer)."""
    k = math.floor(LADDER * math.log2(cell_m))
    while 2.0 ** ((k + 1) / LADDER) <= cell_m:
        k += 1
    while 2.0 ** (k / LADDER) > cell_m:
        k -= 1
    return k, 2.0 ** (k / LADDER)
