"""Reading a digital elevation model from a file, within stated bounds: the one module that opens rasters.

A DEM is a single-band raster GDAL reads through rasterio (GeoTIFF in a
geographic or projected CRS, DTED ``.dt0/.dt1/.dt2``, SRTM ``.hgt``), its
values metres above the vertical datum it was made on.  Everything else is
refused with an ``InputError`` naming the file, so a CLI prints one line and
exits 2: a file that is not a raster, a driver outside ``DRIVERS`` (a VRT may
name other files or URLs), more than one band, no CRS (it cannot be placed),
a declared size or block beyond ``bounds.LIMITS`` (``dem_side_cells``,
``dem_block_cells``: a small file that declares a huge block is a
decompression bomb, and GDAL decompresses a block whole), and an area whose
cells exceed ``dem_cells`` after cropping.  Only the window that covers the
area asked for is read, so memory is the window's, never the file's.

No-data: holes up to ``FILL_CELLS`` cells from known ground are filled by
GDAL's inverse-distance interpolation (``fillnodata``); farther cells stay NaN,
unknown ground.  Beyond the DEM's edges nothing is known: an area asked for
must lie within the DEM, or it is refused.  docs/terrain.md states what each
consumer makes of unknown ground.
"""

from __future__ import annotations

import math
import os
import stat
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np

from pfp_service.bounds import LIMITS
from pfp_service.errors import InputError

__all__ = ["DRIVERS", "FILL_CELLS", "Dem", "DemInfo", "check", "info", "read_dem", "to_dem_crs", "write_mask"]

DRIVERS = frozenset({"GTiff", "DTED", "SRTMHGT"})
FILL_CELLS = 8  # a hole this far from known ground is interpolated; a wider one stays unknown
# GDAL's block cache, MB: the reads below are windows of at most LIMITS["dem_cells"], so the cache
# only needs the blocks one row of the window crosses.
_GDAL_ENV = {"GDAL_CACHEMAX": 64, "GDAL_DISABLE_READDIR_ON_OPEN": "EMPTY_DIR", "GDAL_PAM_ENABLED": "NO"}
# Elevations outside these are not metres of ground (a photo's pixels, a float raster of something else).
_MIN_ELEVATION_M, _MAX_ELEVATION_M = -1_000.0, 9_000.0


@dataclass(frozen=True)
class Dem:
    """A window of a DEM in its own CRS: elevations (NaN unknown) and the affine of the window.

    ``elevation[row, col]`` is the ground at the centre of the cell whose
    corner ``transform @ (col, row)`` gives in CRS units.
    """

    path: str
    elevation: np.ndarray
    transform: Any  # affine.Affine of this window
    crs: Any  # rasterio.crs.CRS
    filled_cells: int  # holes interpolated
    unknown_cells: int  # left NaN


@dataclass(frozen=True)
class DemInfo:
    """What ``pfp terrain info`` shows."""

    path: str
    driver: str
    crs: str
    width: int
    height: int
    bounds_latlon: tuple[float, float, float, float]  # south, west, north, east
    resolution_m: tuple[float, float]  # a cell's width and height at the centre
    elevation_min_m: float | None
    elevation_max_m: float | None
    elevation_sampled: bool  # read from an overview, or not read (min and max None), to stay within dem_cells
    nodata_cells: int


@contextmanager
def _open(path: str) -> Iterator[Any]:
    """The checked rasterio dataset of ``path``."""
    try:
        import rasterio
        from rasterio.errors import RasterioIOError
    except ImportError:  # the `terrain` extra is not installed
        raise InputError(path, "reading a DEM needs rasterio: pip install 'pfp-service[terrain]'") from None

    try:
        mode = os.stat(path).st_mode
    except OSError as exc:
        raise InputError(path, f"cannot read: {exc.strerror or exc}") from None
    if stat.S_ISDIR(mode):
        raise InputError(path, "is a directory, not a DEM")
    if not stat.S_ISREG(mode):
        raise InputError(path, "is not a regular file")
    # rasterio warns (a raster without georeferencing) where this module refuses with one line
    with rasterio.Env(**_GDAL_ENV), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            ds = rasterio.open(path, allowed_drivers=sorted(DRIVERS))
        except RasterioIOError:
            raise InputError(
                path, f"is not a DEM: not a raster GDAL reads as {', '.join(sorted(DRIVERS))}"
            ) from None
        with ds:
            _check(path, ds)
            yield ds


def _check(path: str, ds: Any) -> None:
    side = LIMITS["dem_side_cells"].value
    if ds.width > side or ds.height > side:
        raise InputError(
            path, f"declares {ds.width:,} x {ds.height:,} cells, more than {side:,} a side (dem_side_cells)"
        )
    if ds.count != 1:
        raise InputError(path, f"has {ds.count} bands: a DEM has one")
    kind = np.dtype(ds.dtypes[0]).kind
    if kind not in "iuf":
        raise InputError(path, f"holds {ds.dtypes[0]} values, not elevations")
    bh, bw = ds.block_shapes[0]
    if bh * bw > LIMITS["dem_block_cells"].value:
        raise InputError(
            path,
            f"stores blocks of {bw:,} x {bh:,} cells, more than {LIMITS['dem_block_cells'].value:,} "
            "decompressed at once (dem_block_cells)",
        )
    if ds.crs is None:
        raise InputError(path, "has no coordinate reference system: it cannot be placed")
    try:
        s, w, n, e = _latlon_bounds(ds)
    except Exception:  # PROJ refuses: an engineering CRS, a local one, a broken definition
        raise InputError(
            path, "its CRS cannot be placed: PROJ knows no way from it to latitude and longitude"
        ) from None
    if not all(map(math.isfinite, (s, w, n, e))) or not (-90 <= s <= n <= 90):
        raise InputError(path, "its CRS cannot be placed on WGS-84 (its corners fall off the earth)")


def to_dem_crs(crs: Any, lat: np.ndarray, lon: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """WGS-84 degrees to the DEM's CRS coordinates (x, y), through PROJ (datum shifts included)."""
    from rasterio.warp import transform

    if crs.to_epsg() == 4326:
        return np.asarray(lon, dtype=float), np.asarray(lat, dtype=float)
    x, y = transform("EPSG:4326", crs, np.asarray(lon, dtype=float), np.asarray(lat, dtype=float))
    return np.asarray(x, dtype=float), np.asarray(y, dtype=float)


def _latlon_bounds(ds: Any) -> tuple[float, float, float, float]:
    from rasterio.warp import transform_bounds

    west, south, east, north = transform_bounds(ds.crs, "EPSG:4326", *ds.bounds, densify_pts=21)
    return south, west, north, east


def _resolution_m(ds: Any) -> tuple[float, float]:
    """A cell's width and height in metres at the raster's centre, through the planner's own plane."""
    from rasterio.warp import transform as warp

    from pfp_service.geo import Origin

    col, row = ds.width / 2.0, ds.height / 2.0
    pts = [ds.transform @ (col + a, row + b) for a, b in ((0, 0), (1, 0), (0, 1))]
    lon, lat = warp(ds.crs, "EPSG:4326", [p[0] for p in pts], [p[1] for p in pts])
    o = Origin(lat=lat[0], lon=lon[0])
    xy = o.to_local_many(np.column_stack([lat, lon]))
    return float(np.hypot(*(xy[1] - xy[0]))), float(np.hypot(*(xy[2] - xy[0])))


def check(path: str) -> None:
    """Refuse ``path`` now if its header breaks a bound or it is no DEM (what ``read_dem`` would say), reading no cell.

    Raises:
        InputError: the file is not a DEM this module reads, or breaks a bound.
    """
    with _open(path):
        pass


def info(path: str) -> DemInfo:
    """The DEM's description, its elevation range read within ``dem_cells``.

    A DEM of more cells is read through its smallest overview that fits, if it has one;
    without one its range is left unknown (``None``), since a decimated read of it would
    still decompress every block: bounded memory, unbounded time.

    Raises:
        InputError: the file is not a DEM this module reads, or breaks a bound.
    """
    with _open(path) as ds:
        budget = LIMITS["dem_cells"].value
        step = 1
        if ds.width * ds.height > budget:
            fits = [f for f in ds.overviews(1) if (ds.width // f) * (ds.height // f) <= budget]
            step = min(fits) if fits else 0
        lo = hi = None
        nodata = 0
        if step:
            z = _masked(path, ds, None, (max(1, ds.height // step), max(1, ds.width // step)))
            known = z[np.isfinite(z)]
            if known.size:
                lo, hi = float(known.min()), float(known.max())
            nodata = int(z.size - known.size) * step * step
        return DemInfo(
            path=path,
            driver=ds.driver,
            crs=ds.crs.to_string(),
            width=ds.width,
            height=ds.height,
            bounds_latlon=_latlon_bounds(ds),
            resolution_m=_resolution_m(ds),
            elevation_min_m=lo,
            elevation_max_m=hi,
            elevation_sampled=step != 1,
            nodata_cells=nodata,
        )


def _masked(path: str, ds: Any, window: Any, shape: tuple[int, int] | None = None) -> np.ndarray:
    """Band 1 over ``window`` as float64, NaN where the file says no data or the value is not ground."""
    from rasterio.errors import RasterioError

    try:
        a = ds.read(1, window=window, out_shape=shape, masked=True, boundless=False)
    except (RasterioError, MemoryError) as exc:
        raise InputError(path, f"cannot be read: {exc}") from None
    z = np.asarray(np.ma.filled(np.ma.asarray(a).astype(np.float64), np.nan))
    with np.errstate(invalid="ignore"):
        z[~((z >= _MIN_ELEVATION_M) & (z <= _MAX_ELEVATION_M))] = np.nan
    return z


def read_dem(
    path: str, area_latlon: tuple[float, float, float, float] | None = None, clip: bool = False
) -> Dem:
    """The DEM's cells covering ``area_latlon`` (south, west, north, east), or all of it, holes filled.

    With ``clip``, an area reaching past the DEM is cut to it (a viewshed near the edge) instead of refused.

    Raises:
        InputError: not a DEM, the area not within it, or more than ``dem_cells`` cells to read.
    """
    from rasterio.fill import fillnodata
    from rasterio.windows import Window, from_bounds

    with _open(path) as ds:
        if area_latlon is None:
            window = Window(0, 0, ds.width, ds.height)
        else:
            window = _window(path, ds, area_latlon, from_bounds, clip)
        budget = LIMITS["dem_cells"].value
        cells = int(window.width) * int(window.height)
        if cells > budget:
            raise InputError(
                path,
                f"the area asked for is {int(window.width):,} x {int(window.height):,} cells, more than "
                f"{budget:,} (dem_cells): crop it smaller",
            )
        z = _masked(path, ds, window)
        transform = ds.window_transform(window)
        crs = ds.crs
    holes = ~np.isfinite(z)
    filled = 0
    if holes.any() and not holes.all():
        # GDAL interpolates the holes from the mask alone and leaves what it cannot reach as it was: NaN
        z = np.asarray(
            fillnodata(z, mask=(~holes).astype(np.uint8), max_search_distance=FILL_CELLS), dtype=np.float64
        )
        filled = int(holes.sum()) - int((~np.isfinite(z)).sum())
    unknown = int((~np.isfinite(z)).sum())
    if unknown == z.size:
        raise InputError(path, "holds no ground in the area asked for: every cell is no-data")
    return Dem(path, z, transform, crs, filled, unknown)


def _window(path: str, ds: Any, area: tuple[float, float, float, float], from_bounds: Any, clip: bool) -> Any:
    south, west, north, east = area
    lat = np.array([south, south, north, north, (south + north) / 2, (south + north) / 2])
    lon = np.array([west, east, west, east, west, east])
    x, y = to_dem_crs(ds.crs, lat, lon)
    left, right, bottom, top = x.min(), x.max(), y.min(), y.max()
    b = ds.bounds
    slack_x, slack_y = abs(ds.transform.a) * 1e-6, abs(ds.transform.e) * 1e-6
    if clip:
        left, right = max(left, b.left), min(right, b.right)
        bottom, top = max(bottom, b.bottom), min(top, b.top)
        if left >= right or bottom >= top:
            raise InputError(path, "does not reach the area asked for")
    if (
        left < b.left - slack_x
        or right > b.right + slack_x
        or bottom < b.bottom - slack_y
        or top > b.top + slack_y
    ):
        s, w, n, e = _latlon_bounds(ds)
        raise InputError(
            path,
            f"does not cover the area asked for (lat {south:.5f}..{north:.5f}, lon {west:.5f}..{east:.5f}); "
            f"it covers lat {s:.5f}..{n:.5f}, lon {w:.5f}..{e:.5f}",
        )
    win = from_bounds(left, bottom, right, top, transform=ds.transform)
    # whole cells, one more on each side for bilinear sampling, clipped to the raster
    from rasterio.windows import Window

    c0 = max(0, math.floor(win.col_off) - 1)
    r0 = max(0, math.floor(win.row_off) - 1)
    c1 = min(ds.width, math.ceil(win.col_off + win.width) + 1)
    r1 = min(ds.height, math.ceil(win.row_off + win.height) + 1)
    return Window(c0, r0, c1 - c0, r1 - r0)


def write_mask(path: str, mask: np.ndarray, dem: Dem) -> None:
    """``mask`` (uint8, the DEM window's shape) as a one-band GeoTIFF on the DEM window's grid.

    Raises:
        InputError: path ``path``; it cannot be written.
    """
    import rasterio
    from rasterio.errors import RasterioError

    try:
        with (
            rasterio.Env(**_GDAL_ENV),
            rasterio.open(
                path,
                "w",
                driver="GTiff",
                width=mask.shape[1],
                height=mask.shape[0],
                count=1,
                dtype="uint8",
                crs=dem.crs,
                transform=dem.transform,
                compress="deflate",
            ) as out,
        ):
            out.write(mask.astype(np.uint8), 1)
    except (RasterioError, OSError) as exc:
        raise InputError(path, f"cannot be written: {exc}") from None
