"""The ground under the map (``pfp map --terrain DEM``): a hillshade overlay, and a threat's viewshed on request.

Leaflet draws an ``imageOverlay`` between two lat/lon corners, stretched
linearly in Web Mercator.  So each image here is made on that grid, whatever
the DEM's CRS: columns equally spaced in longitude, rows equally spaced in
Mercator y, north first (``mercator_grid``), and each pixel takes the DEM's
value at its centre (a UTM DEM's grid convergence, a geographic DEM's
unequal degrees, are absorbed there).

- The hillshade is ``render.terrain_layers.hillshade`` (the plot's, lit from
  the north-west) of the DEM placed on the map's plane (``terrain.grid.place``,
  square cells at about the DEM's resolution), sampled bilinearly at each
  pixel: grey, opaque where the ground is known, transparent elsewhere.
- A viewshed is ``terrain.sight.observe`` (``pfp terrain viewshed``'s: Wang's
  sweep on the DEM's own cells) from the threat's position at its
  ``observer_height_m``, out to its reach (``core.visibility.reach_box``),
  and each pixel shows its DEM cell: seen (translucent blue) or not
  (transparent).  The visible cells are those where a target ``target_height_m``
  above the ground is seen.

Bounded: an image is at most ``MAX_SIDE`` pixels a side, a viewshed's radius at
most ``MAX_RADIUS_M`` (so its sweep covers at most about ``(2 MAX_RADIUS_M /
cell)**2`` cells), and the server computes viewsheds one at a time on one
worker thread, each result kept (``Viewsheds``, ``CACHE`` of them) by the
threat's position, eye, reach and target height.
"""

from __future__ import annotations

import base64
import math
import os
import struct
import zlib
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any

import numpy as np

from pfp_clients.ground import Ground
from pfp_service.errors import InputError
from pfp_service.geo import Origin
from pfp_service.wire import ThreatUpdate

__all__ = [
    "MAX_RADIUS_M",
    "MAX_SIDE",
    "Overlay",
    "Viewsheds",
    "hillshade_overlay",
    "mercator_grid",
    "png_rgba",
    "threat_reach_m",
    "viewshed_overlay",
]

MAX_SIDE = 1024  # pixels a side of an overlay: a browser draws it at once, and it stays a few hundred kB
MAX_RADIUS_M = 10_000.0  # a viewshed reaches this far at most, whatever the threat's reach
MIN_RADIUS_M = 100.0  # and at least this far: a threat of a few metres still shows its ground
CACHE = 64  # viewsheds kept
SEEN_RGBA = (25, 118, 210, 150)  # translucent blue: not one of the threat reds


@dataclass(frozen=True)
class Overlay:
    """An image for ``L.imageOverlay``: its PNG and its corners ``[[south, west], [north, east]]``."""

    png: bytes
    bounds: tuple[tuple[float, float], tuple[float, float]]
    extra: dict[str, Any]

    def view(self) -> dict[str, Any]:
        """JSON for the page: the PNG as a data URL, the corners, and what ``extra`` says."""
        url = "data:image/png;base64," + base64.b64encode(self.png).decode()
        return {"image": url, "bounds": [list(self.bounds[0]), list(self.bounds[1])], **self.extra}


def png_rgba(rgba: np.ndarray) -> bytes:
    """``(rows, cols, 4)`` uint8 as a PNG (8-bit RGBA, no interlace)."""
    a = np.ascontiguousarray(rgba, dtype=np.uint8)
    h, w = a.shape[:2]
    raw = np.concatenate([np.zeros((h, 1), np.uint8), a.reshape(h, w * 4)], axis=1).tobytes()

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    head = struct.pack(">IIBBBBB", w, h, 8, 6, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", head)
        + chunk(b"IDAT", zlib.compress(raw, 6))
        + chunk(b"IEND", b"")
    )


def _merc_y(lat_deg: np.ndarray | float) -> np.ndarray:
    return np.log(np.tan(np.pi / 4 + np.radians(lat_deg) / 2))


def mercator_grid(
    bounds: tuple[float, float, float, float], cols: int, rows: int
) -> tuple[np.ndarray, np.ndarray]:
    """Pixel centres of an image over ``bounds`` (south, west, north, east) as Leaflet stretches it.

    Returns:
        ``(lat, lon)``: ``rows`` latitudes, north first, equally spaced in Mercator y, and ``cols``
        longitudes, west first.
    """
    s, w, n, e = bounds
    y0, y1 = float(_merc_y(n)), float(_merc_y(s))
    y = y0 + (np.arange(rows) + 0.5) * (y1 - y0) / rows
    lat = np.degrees(2 * np.arctan(np.exp(y)) - np.pi / 2)
    lon = w + (np.arange(cols) + 0.5) * (e - w) / cols
    return lat, lon


def _size(ground: Ground, bounds: tuple[float, float, float, float]) -> tuple[int, int]:
    """About one pixel per DEM cell over ``bounds``, at most ``MAX_SIDE`` a side."""
    s, w, n, e = ground.bounds_latlon
    rows, cols = ground.dem.elevation.shape
    fc = (bounds[3] - bounds[1]) / max(e - w, 1e-12)
    fr = (bounds[2] - bounds[0]) / max(n - s, 1e-12)
    return max(2, min(MAX_SIDE, round(cols * fc))), max(2, min(MAX_SIDE, round(rows * fr)))


def hillshade_overlay(ground: Ground, origin: Origin) -> Overlay:
    """The DEM's hillshade over its whole box, grey where known and transparent elsewhere."""
    from pfp_service.render.terrain_layers import hillshade
    from pfp_service.terrain.grid import TerrainGrid, bilinear, place
    from pfp_service.terrain.sight import cell_metres

    bounds = ground.bounds_latlon
    s, w, n, e = bounds
    corners = np.array([[lat, lon] for lat in (s, (s + n) / 2, n) for lon in (w, (w + e) / 2, e)])
    xy = origin.to_local_many(corners)
    box = (float(xy[:, 0].min()), float(xy[:, 1].min()), float(xy[:, 0].max()), float(xy[:, 1].max()))
    rows, cols = ground.dem.elevation.shape
    native = min(cell_metres(ground.dem, rows // 2, cols // 2))
    # about the DEM's cells, and no more than the image's pixels need
    cell = max(native, math.sqrt((box[2] - box[0]) * (box[3] - box[1])) / MAX_SIDE)
    grid: TerrainGrid = place(ground.dem, origin, box, cell)
    shade = hillshade(grid.z, grid.cell_m)
    width, height = _size(ground, bounds)
    lat, lon = mercator_grid(bounds, width, height)
    glat, glon = np.meshgrid(lat, lon, indexing="ij")
    pxy = origin.to_local_many(np.column_stack([glat.ravel(), glon.ravel()]))
    v = bilinear(shade, (pxy[:, 0] - grid.x0_m) / grid.cell_m, (pxy[:, 1] - grid.y0_m) / grid.cell_m)
    v = v.reshape(height, width)
    known = np.isfinite(v)
    grey = np.where(known, 255 * np.clip(v, 0.0, 1.0), 0).astype(np.uint8)
    rgba = np.stack([grey, grey, grey, np.where(known, 255, 0).astype(np.uint8)], axis=-1)
    return Overlay(png_rgba(rgba), ((s, w), (n, e)), {"path": ground.path, "cell_m": round(grid.cell_m, 2)})


def viewshed_overlay(
    ground: Ground, lat: float, lon: float, observer_height_m: float, radius_m: float, target_height_m: float
) -> Overlay:
    """Where a threat at ``(lat, lon)`` sees a target ``target_height_m`` tall, within ``radius_m``.

    Raises:
        InputError: the observer is off the DEM or on no-data (``threat``).
    """
    from pfp_service.terrain.sight import observe
    from pfp_service.terrain.viewshed import visible

    row, col = ground.cells(np.array([lat]), np.array([lon]))
    rows, cols = ground.dem.elevation.shape
    if not (0 <= math.floor(row[0] + 0.5) < rows and 0 <= math.floor(col[0] + 0.5) < cols):
        raise InputError("threat", f"{lat:.6f},{lon:.6f} is outside the DEM {os.path.basename(ground.path)}")
    sight = observe(ground.path, lat, lon, observer_height_m, radius_m, 0.0, flag="threat")
    seen = visible(sight.lowest_m, target_height_m)
    o = Origin(lat=lat, lon=lon)
    r = radius_m * 1.001
    ring = o.to_geodetic_many(np.array([[a * r, b * r] for a in (-1, 0, 1) for b in (-1, 0, 1)]))
    gs, gw, gn, ge = ground.bounds_latlon
    bounds = (
        max(gs, float(ring[:, 0].min())),
        max(gw, float(ring[:, 1].min())),
        min(gn, float(ring[:, 0].max())),
        min(ge, float(ring[:, 1].max())),
    )
    width, height = _size(ground, bounds)
    plat, plon = mercator_grid(bounds, width, height)
    glat, glon = np.meshgrid(plat, plon, indexing="ij")
    # each pixel shows the cell of the viewshed's window its centre falls in
    x, y = _dem_xy(sight.dem, glat.ravel(), glon.ravel())
    col, row = ~sight.dem.transform @ (x, y)
    ri, ci = np.floor(row).astype(np.intp), np.floor(col).astype(np.intp)
    nr, nc = seen.shape
    inside = (ri >= 0) & (ri < nr) & (ci >= 0) & (ci < nc)
    hit = np.zeros(ri.shape, dtype=bool)
    hit[inside] = seen[ri[inside], ci[inside]]
    hit = hit.reshape(height, width)
    rgba = np.zeros((height, width, 4), np.uint8)
    rgba[hit] = SEEN_RGBA
    within = np.isfinite(sight.lowest_m)
    return Overlay(
        png_rgba(rgba),
        ((bounds[0], bounds[1]), (bounds[2], bounds[3])),
        {
            "observer": [lat, lon],
            "observer_height_m": observer_height_m,
            "target_height_m": target_height_m,
            "radius_m": round(radius_m, 1),
            "cells": int(within.sum()),
            "seen_cells": int(seen.sum()),
            "cell_m": [round(sight.dx_m, 2), round(sight.dy_m, 2)],
        },
    )


def _dem_xy(dem: Any, lat: np.ndarray, lon: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    from pfp_service.terrain.dem import to_dem_crs

    return to_dem_crs(dem.crs, lat, lon)


def threat_reach_m(update: ThreatUpdate, threat_id: str) -> float:
    """How far the threat's term reaches (``core.visibility.reach_box``), within ``MIN``/``MAX_RADIUS_M``."""
    from pfp_service.core.threat import ThreatField
    from pfp_service.core.visibility import reach_box
    from pfp_service.world import translate

    row = ThreatField([translate.threat(update, threat_id)], "peak").packed[0]
    x0, y0, x1, y1 = reach_box(row)
    return float(min(MAX_RADIUS_M, max(MIN_RADIUS_M, 0.5 * (x1 - x0), 0.5 * (y1 - y0))))


class Viewsheds:
    """Viewsheds kept by what decides them (position, eye, reach, target), least recently used out.

    Used from the event loop only: ``compute`` is the blocking part, run on the viewshed thread.
    """

    def __init__(self, ground: Ground, target_height_m: float, size: int = CACHE) -> None:
        self.ground = ground
        self.target_height_m = target_height_m
        self._kept: OrderedDict[tuple[float, ...], Overlay] = OrderedDict()
        self._size = size
        self.computed = 0

    def key(self, lat: float, lon: float, observer_height_m: float, radius_m: float) -> tuple[float, ...]:
        return (round(lat, 7), round(lon, 7), observer_height_m, round(radius_m, 1), self.target_height_m)

    def get(self, key: tuple[float, ...]) -> Overlay | None:
        got = self._kept.get(key)
        if got is not None:
            self._kept.move_to_end(key)
        return got

    def keep(self, key: tuple[float, ...], overlay: Overlay) -> None:
        self.computed += 1
        self._kept[key] = overlay
        if len(self._kept) > self._size:
            self._kept.popitem(last=False)

    def compute(self, key: tuple[float, ...]) -> Overlay:
        """The viewshed of ``key`` (blocking, touches nothing of ``self`` but the DEM)."""
        lat, lon, eye, radius, target = key
        return viewshed_overlay(self.ground, lat, lon, eye, radius, target)
