"""Real ground to test terrain on: matplotlib's Jacksboro fault DEM written as GeoTIFF (geographic and UTM)
and DTED, with rasterio only (no gdal-bin), and the cells the tests put observers on.

The DEM (``jacksboro_fault_dem.npz``) is 344 x 403 cells of 3 arc-seconds; its
``xmin``/``xmax`` are the west and east edges, and ``ymin`` (36.733) is the
latitude of the first row's north edge, ``ymax`` (36.446) the last row's south
edge, as the cell count times ``dy`` confirms.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

ARCSEC = 1.0 / 3600.0


def jacksboro() -> tuple[np.ndarray, float, float, float]:
    """(elevation int16 rows north to south, west edge, north edge, cell size in degrees)."""
    from matplotlib import cbook

    d = cbook.get_sample_data("jacksboro_fault_dem.npz")
    z = np.asarray(d["elevation"])
    west, north, step = float(d["xmin"]), float(d["ymin"]), float(d["dx"])
    assert abs(float(d["xmin"]) + z.shape[1] * step - float(d["xmax"])) < 1e-9
    assert abs(north - z.shape[0] * float(d["dy"]) - float(d["ymax"])) < 1e-9
    return z, west, north, step


def write_geographic(path: Path) -> Path:
    """The sample DEM as ``pfp demo --terrain`` writes it (``pfp_clients.sample_dem``)."""
    from pfp_clients.sample_dem import write_jacksboro

    return write_jacksboro(path)


def write_utm(src: Path, path: Path) -> Path:
    """``src`` reprojected to UTM 16N (EPSG:32616) at about its own resolution, bilinear."""
    import rasterio
    from rasterio.warp import Resampling, calculate_default_transform, reproject

    with rasterio.open(src) as s:
        transform, width, height = calculate_default_transform(
            s.crs, "EPSG:32616", s.width, s.height, *s.bounds
        )
        z = np.full((height, width), -32768, dtype=np.int16)
        reproject(
            rasterio.band(s, 1), z, dst_transform=transform, dst_crs="EPSG:32616",
            resampling=Resampling.bilinear, dst_nodata=-32768,
        )  # fmt: skip
    with rasterio.open(
        path, "w", driver="GTiff", width=width, height=height, count=1, dtype="int16",
        crs="EPSG:32616", transform=transform, nodata=-32768,
    ) as out:  # fmt: skip
        out.write(z, 1)
    return path


def write_dted(path: Path) -> Path:
    """The DEM inside its DTED level 1 cell (N36 W085: 1201 x 1201 posts of 3"), the rest no-data.

    DTED posts sit on whole arc-seconds and GDAL puts its cell corners half a post
    before them, so the DEM's 3" cells, whose edges are whole multiples of 1.5",
    land exactly on posts.
    """
    import rasterio
    import rasterio.shutil
    from rasterio.transform import from_origin

    z, west, north, step = jacksboro()
    n = 1201
    origin_w, origin_n = -85.0 - 1.5 * ARCSEC, 37.0 + 1.5 * ARCSEC
    col0 = round((west - origin_w) / step)
    row0 = round((origin_n - north) / step)
    assert abs(origin_w + col0 * step - west) < 1e-9 and abs(origin_n - row0 * step - north) < 1e-9
    tile = np.full((n, n), -32767, dtype=np.int16)
    tile[row0 : row0 + z.shape[0], col0 : col0 + z.shape[1]] = z
    mem = path.with_suffix(".tmp.tif")
    with rasterio.open(
        mem, "w", driver="GTiff", width=n, height=n, count=1, dtype="int16", crs="EPSG:4326",
        transform=from_origin(origin_w, origin_n, step, step), nodata=-32767,
    ) as out:  # fmt: skip
        out.write(tile, 1)
    rasterio.shutil.copy(mem, path, driver="DTED")
    mem.unlink()
    return path


def build(directory: Path) -> dict[str, Path]:
    """The three files: ``geographic``, ``utm`` and ``dted``."""
    geo = write_geographic(directory / "jacksboro.tif")
    return {
        "geographic": geo,
        "utm": write_utm(geo, directory / "jacksboro-utm16n.tif"),
        "dted": write_dted(directory / "n36_w085.dt1"),
    }


def observers(z: np.ndarray, margin: int) -> dict[str, tuple[int, int]]:
    """A ridge, a slope and a valley cell of ``z`` (NaN unknown), at least ``margin`` cells from its edges.

    The ridge is the highest cell, the valley the lowest, and the slope the cell whose
    elevation is nearest the middle of the two where the ground is steepest.
    """
    inner = np.full(z.shape, np.nan)
    inner[margin:-margin, margin:-margin] = z[margin:-margin, margin:-margin]
    gy, gx = np.gradient(np.where(np.isfinite(inner), inner, np.nanmean(inner)))
    steep = np.hypot(gx, gy)
    mid = (np.nanmax(inner) + np.nanmin(inner)) / 2
    score = np.where(np.isfinite(inner) & (np.abs(inner - mid) < 100), steep, -1.0)
    pick = {
        "ridge": np.nanargmax(inner),
        "valley": np.nanargmin(inner),
        "slope": int(np.argmax(score)),
    }
    return {k: (int(v // z.shape[1]), int(v % z.shape[1])) for k, v in pick.items()}
