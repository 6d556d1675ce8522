"""Terrain: one observer's viewshed on 1,000 x 1,000 cells within 5 km, against gdal_viewshed in the same run.

The grid is matplotlib's Jacksboro fault DEM (ridge-and-valley ground in
Tennessee, 3 arc-seconds) placed on the planner's plane around its centre at
``--cell`` metres (10 by default, so 1,001 x 1,001 points over 10 km), with
the observer ``--height`` above the centre.  The sweep
(``terrain.viewshed.lowest_visible_height``) is timed after a warm-up, in
process; ``gdal_viewshed`` (Debian's gdal-bin) on the same grid written as a
GeoTIFF is timed as a program, so its figure includes its start and its file
I/O; both are printed with the load average.  The two are also compared
cell by cell, where an exact ray (sampled) confirms GDAL.

Target (issue 32): <= 50 ms for one observer's visibility over 1,000 x 1,000
cells within a 5 km reach.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any

TARGET_MS = 50.0
RADIUS_M = 5_000.0
CURVATURE = 0.85714  # gdal_viewshed's default -cc, passed to both


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--cell", type=float, default=10.0, help="grid spacing in metres (default: 10)")
    p.add_argument("--repeat", type=int, default=20, help="timed sweeps after the warm-up (default: 20)")
    p.add_argument("--height", type=float, default=2.0, help="the observer's eye above ground (default: 2)")
    p.add_argument("--check", action="store_true", help="exit 1 when a target is missed")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def _grid(cell_m: float):  # type: ignore[no-untyped-def]
    """The Jacksboro DEM on the planner's plane, +-5 km around its centre (``TerrainGrid``, origin)."""
    import numpy as np
    from matplotlib import cbook

    from pfp_service.geo import Origin
    from pfp_service.terrain.dem import Dem
    from pfp_service.terrain.grid import place

    d: Any = cbook.get_sample_data("jacksboro_fault_dem.npz")  # an NpzFile; its stubs say IO too
    z = np.asarray(d["elevation"], dtype=float)
    west, north, step = float(d["xmin"]), float(d["ymin"]), float(d["dx"])
    from rasterio.crs import CRS
    from rasterio.transform import from_origin

    dem = Dem("jacksboro", z, from_origin(west, north, step, step), CRS.from_epsg(4326), 0, 0)
    origin = Origin(lat=north - z.shape[0] * step / 2, lon=west + z.shape[1] * step / 2)
    half = RADIUS_M
    return place(dem, origin, (-half, -half, half, half), cell_m), origin


def _write(path: Path, grid, origin) -> None:  # type: ignore[no-untyped-def]
    """The grid as a GeoTIFF, rows north first, in the orthographic projection at the origin (metres)."""
    import numpy as np
    import rasterio
    from rasterio.transform import from_origin

    z = np.ascontiguousarray(grid.z[::-1]).astype(np.float32)
    top = grid.y0_m + (grid.shape[0] - 0.5) * grid.cell_m
    left = grid.x0_m - 0.5 * grid.cell_m
    crs = f"+proj=ortho +lat_0={origin.lat} +lon_0={origin.lon} +ellps=WGS84 +units=m"
    with rasterio.open(
        path, "w", driver="GTiff", width=z.shape[1], height=z.shape[0], count=1, dtype="float32",
        crs=crs, transform=from_origin(left, top, grid.cell_m, grid.cell_m),
    ) as out:  # fmt: skip
        out.write(z, 1)


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from pfp_service.terrain.viewshed import exact_lowest_visible_height, lowest_visible_height

    load_before = os.getloadavg()
    grid, origin = _grid(args.cell)
    z = grid.z[::-1]  # rows north first, as the GeoTIFF gdal_viewshed reads
    obs = (z.shape[0] // 2, z.shape[1] // 2)
    cell = grid.cell_m

    def sweep():  # type: ignore[no-untyped-def]
        return lowest_visible_height(z, obs, args.height, RADIUS_M, cell, cell, CURVATURE)

    t0 = time.perf_counter()
    ours = sweep()
    first_ms = (time.perf_counter() - t0) * 1e3
    times = []
    for _ in range(max(1, args.repeat)):
        t0 = time.perf_counter()
        ours = sweep()
        times.append((time.perf_counter() - t0) * 1e3)
    inside = np.isfinite(ours)
    out: dict[str, object] = {
        "grid": list(z.shape),
        "cell_m": cell,
        "cells_within_radius": int(inside.sum()),
        "seen_share": float((ours[inside] <= 0).mean()),
        "sweep_ms_median": statistics.median(times),
        "sweep_ms_min": min(times),
        "sweep_ms_first_call": first_ms,
    }
    # the exact ray on a seeded sample of cells within the radius
    rng = np.random.default_rng(32)
    rr, cc = np.nonzero(inside)
    pick = rng.choice(rr.size, size=min(20_000, rr.size), replace=False)
    cells = np.column_stack([rr[pick], cc[pick]])
    t0 = time.perf_counter()
    exact = exact_lowest_visible_height(z, obs, args.height, cells, cell, cell, CURVATURE)
    out["exact_ray_ms_per_1000_cells"] = (time.perf_counter() - t0) * 1e3 / cells.shape[0] * 1000
    ray = exact <= 0
    mine = ours[cells[:, 0], cells[:, 1]] <= 0
    out["agree_with_exact_ray"] = float((mine == ray).mean())
    gdal = shutil.which("gdal_viewshed")
    if gdal is None:
        out["gdal_viewshed"] = "not installed (apt-get install gdal-bin)"
    else:
        out.update(_gdal(gdal, grid, origin, obs, args.height, ours, cells, ray))
    out["load_average"] = {"before": list(load_before), "after": list(os.getloadavg())}
    met = out["sweep_ms_median"] <= TARGET_MS  # type: ignore[operator]
    if args.json:
        print(json.dumps(out))
    else:
        _print(out, met)
    return 1 if args.check and not met else 0


def _gdal(gdal, grid, origin, obs, height, ours, cells, ray) -> dict[str, object]:  # type: ignore[no-untyped-def]
    import numpy as np
    import rasterio

    with tempfile.TemporaryDirectory(prefix="pfp-bench-terrain-") as tmp:
        src, dst = Path(tmp) / "grid.tif", Path(tmp) / "seen.tif"
        _write(src, grid, origin)
        with rasterio.open(src) as f:
            x, y = f.transform @ (obs[1] + 0.5, obs[0] + 0.5)
            t0, shape = f.transform, f.shape
        cmd = [gdal, "-q", "-oz", str(height), "-tz", "0", "-cc", str(CURVATURE), "-md", str(RADIUS_M)]
        cmd += ["-ox", repr(x), "-oy", repr(y), str(src), str(dst)]
        times = []
        for _ in range(3):
            t = time.perf_counter()
            subprocess.run(cmd, check=True, capture_output=True, timeout=300)
            times.append((time.perf_counter() - t) * 1e3)
        with rasterio.open(dst) as f:
            g, t1 = f.read(1), f.transform
    full = np.zeros(shape, np.uint8)
    ro, co = round((t1.f - t0.f) / t0.e), round((t1.c - t0.c) / t0.a)
    full[ro : ro + g.shape[0], co : co + g.shape[1]] = g
    seen = full[cells[:, 0], cells[:, 1]] == 255
    mine = ours[cells[:, 0], cells[:, 1]] <= 0
    confirmed = seen == ray
    return {
        "gdal_viewshed_ms_median": statistics.median(times),
        "gdal_viewshed_ms_min": min(times),
        "agree_with_gdal_where_exact_ray_confirms": float((mine == seen)[confirmed].mean()),
        "gdal_agrees_with_exact_ray": float(confirmed.mean()),
    }


def _print(out: dict[str, object], met: bool) -> None:
    g = out["grid"]
    print(f"terrain: viewshed on {g[0]} x {g[1]} cells of {out['cell_m']:g} m, radius {RADIUS_M:g} m")  # type: ignore[index]
    print(f"  cells within the radius     {out['cells_within_radius']:,}, {out['seen_share']:.1%} seen")
    print(
        f"  pfp sweep (in process)      median {out['sweep_ms_median']:.1f} ms, min {out['sweep_ms_min']:.1f} ms"
        f" (first call {out['sweep_ms_first_call']:.0f} ms: compile or cache load)"
    )
    if "gdal_viewshed_ms_median" in out:
        print(
            f"  gdal_viewshed (a program)   median {out['gdal_viewshed_ms_median']:.0f} ms, "
            f"min {out['gdal_viewshed_ms_min']:.0f} ms (with its start and file I/O)"
        )
        print(
            f"  agreement                   {out['agree_with_gdal_where_exact_ray_confirms']:.2%} with GDAL where"
            f" an exact ray confirms it; GDAL with the ray {out['gdal_agrees_with_exact_ray']:.2%}"
        )
    else:
        print(f"  gdal_viewshed               {out['gdal_viewshed']}")
    print(
        f"  exact ray                   {out['agree_with_exact_ray']:.2%} agreement on a 20,000-cell sample,"
        f" {out['exact_ray_ms_per_1000_cells']:.1f} ms per 1,000 cells"
    )
    la = out["load_average"]
    print(f"  load average                {_load(la['before'])} before, {_load(la['after'])} after")  # type: ignore[index]
    mark = "[ok]" if met else "[MISSED]"
    print(f"  {mark} one observer over 1,000 x 1,000 cells within 5 km <= {TARGET_MS:g} ms (median)")


def _load(avg: list[float]) -> str:
    return " ".join(f"{a:.2f}" for a in avg)
