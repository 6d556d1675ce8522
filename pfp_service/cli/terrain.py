"""``pfp terrain``: look at a digital elevation model (DEM) as the planner will read it.

``pfp terrain info DEM`` prints its CRS, bounds in latitude and longitude,
size, cell size in metres and elevation range (``--json`` for one object).
``pfp terrain viewshed DEM --observer LAT,LON --out OUT.tif`` writes where a
target ``--target-height`` metres above the ground is seen from an eye
``--height`` metres above the ground at the observer: a GeoTIFF on the DEM's
grid, 255 seen and 0 not (or beyond ``--radius``), as ``gdal_viewshed``
writes by default.  ``--curvature`` is gdal_viewshed's ``-cc`` (0 a flat
earth).  A DEM is a GeoTIFF, DTED or SRTM .hgt file (docs/terrain.md).

Exit codes: 0 done; 2 a bad file or flag (one line naming it, and why).
"""

from __future__ import annotations

import argparse
import json
import math
from typing import Any

from pfp_service.cli import example_epilog
from pfp_service.cli._common import positive_float

EXAMPLES = {"terrain": "pfp terrain info n36_w085.dt1"}


def register(sub: Any) -> None:
    p = sub.add_parser("terrain", help="describe a DEM, or write a viewshed over it", description=__doc__)
    p.set_defaults(help_parser=p)  # `pfp terrain` alone shows the actions
    inner = p.add_subparsers(dest="action", metavar="ACTION", parser_class=type(p))
    info = inner.add_parser("info", help="CRS, bounds, size, resolution and elevation range of a DEM")
    info.add_argument("dem", metavar="DEM", help="a GeoTIFF, DTED (.dt0/.dt1/.dt2) or SRTM .hgt file")
    info.add_argument("--json", action="store_true", help="print one JSON object")
    info.set_defaults(func=run_info)
    info.epilog = example_epilog("pfp terrain info n36_w085.dt1 --json")
    vs = inner.add_parser("viewshed", help="write where an observer sees, as a GeoTIFF on the DEM's grid")
    vs.add_argument("dem", metavar="DEM", help="a GeoTIFF, DTED (.dt0/.dt1/.dt2) or SRTM .hgt file")
    vs.add_argument("--observer", type=latlon, required=True, metavar="LAT,LON", help="the observer, degrees")
    vs.add_argument("--height", type=height_m, default=2.0, metavar="M", help="the eye above the ground")
    vs.add_argument(
        "--target-height", type=height_m, default=0.0, metavar="M", help="the target above the ground"
    )
    vs.add_argument(
        "--radius", type=positive_float, metavar="M", help="how far to look (default: the whole DEM)"
    )
    vs.add_argument(
        "--curvature",
        type=curvature,
        default=0.85714,
        metavar="K",
        help="earth curvature less refraction, as gdal_viewshed's -cc; 0 for a flat earth",
    )
    vs.add_argument("--out", required=True, metavar="OUT.tif", help="the GeoTIFF to write")
    vs.set_defaults(func=run_viewshed)
    vs.epilog = example_epilog(
        "pfp terrain viewshed n36_w085.dt1 --observer 36.55,-84.3 --height 10 --radius 5000 --out seen.tif"
    )


def latlon(text: str) -> tuple[float, float]:
    """``"LAT,LON"`` in degrees."""
    parts = text.split(",")
    try:
        lat, lon = (float(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected LAT,LON in degrees, got {text!r}") from None
    if not (-90 <= lat <= 90 and -180 <= lon <= 180):
        raise argparse.ArgumentTypeError(f"latitude must be within ±90 and longitude ±180, got {text!r}")
    return lat, lon


def height_m(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected metres, got {text!r}") from None
    if not (math.isfinite(value) and 0 <= value <= 100_000):
        raise argparse.ArgumentTypeError(f"must be metres from 0 to 100,000, got {text!r}")
    return value


def curvature(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (0 <= value <= 1):
        raise argparse.ArgumentTypeError(f"must be from 0 (flat) to 1 (no refraction), got {text!r}")
    return value


def run_info(args: argparse.Namespace) -> int:
    from pfp_service.terrain.dem import info

    d = info(args.dem)
    doc = {
        "path": d.path,
        "driver": d.driver,
        "crs": d.crs,
        "width": d.width,
        "height": d.height,
        "bounds": dict(zip(("south", "west", "north", "east"), d.bounds_latlon)),
        "resolution_m": list(d.resolution_m),
        "elevation_m": {"min": d.elevation_min_m, "max": d.elevation_max_m, "sampled": d.elevation_sampled},
        "nodata_cells": d.nodata_cells,
    }
    if args.json:
        print(json.dumps(doc))
        return 0
    s, w, n, e = d.bounds_latlon
    if d.elevation_min_m is None or d.elevation_max_m is None:
        span = "not read: more cells than dem_cells and no overview" if d.elevation_sampled else "no ground"
    else:
        span = f"{d.elevation_min_m:g}..{d.elevation_max_m:g} m" + (
            " (from an overview)" if d.elevation_sampled else ""
        )
    print(f"{d.path}: {d.driver}, {d.crs}")
    print(f"  size        {d.width} x {d.height} cells")
    print(f"  resolution  {d.resolution_m[0]:.1f} x {d.resolution_m[1]:.1f} m at the centre")
    print(f"  bounds      lat {s:.5f}..{n:.5f}, lon {w:.5f}..{e:.5f}")
    print(f"  elevation   {span}")
    if d.nodata_cells:
        print(f"  no-data     {d.nodata_cells:,} cells")
    return 0


def run_viewshed(args: argparse.Namespace) -> int:
    import numpy as np

    from pfp_service.terrain.dem import write_mask
    from pfp_service.terrain.sight import observe
    from pfp_service.terrain.viewshed import visible

    lat, lon = args.observer
    sight = observe(args.dem, lat, lon, args.height, args.radius, args.curvature)
    seen = visible(sight.lowest_m, args.target_height)
    write_mask(args.out, np.where(seen, 255, 0).astype(np.uint8), sight.dem)
    inside = np.isfinite(sight.lowest_m)
    share = float(seen.sum()) / max(1, int(inside.sum()))
    unknown = int((inside & ~np.isfinite(sight.dem.elevation)).sum())
    print(
        f"{args.out}: {int(seen.sum()):,} of {int(inside.sum()):,} cells seen ({share:.0%}), "
        f"cells {sight.dx_m:.1f} x {sight.dy_m:.1f} m"
        + (f"; {unknown:,} of them no-data, written as seen (docs/terrain.md)" if unknown else "")
    )
    return 0
