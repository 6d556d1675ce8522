"""Real ground for ``pfp demo --terrain``: matplotlib's Jacksboro fault sample DEM written as a GeoTIFF.

344 x 403 cells of 3 arc-seconds (about 74 x 93 m), 236-1,076 m, over
36.446-36.733 N and 84.414-84.078 W: ridge-and-valley country in Tennessee.
matplotlib ships it (``cbook.get_sample_data``); rasterio (the terrain
extra) writes it, and the planner reads it back through its own bounded
reader, as it would any DEM.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["write_jacksboro"]


def write_jacksboro(path: Path) -> Path:
    """Write the sample DEM to ``path`` (GeoTIFF, EPSG:4326, int16 metres); return ``path``."""
    import rasterio
    from matplotlib import cbook
    from rasterio.transform import from_origin

    d: Any = cbook.get_sample_data("jacksboro_fault_dem.npz")
    z = np.asarray(d["elevation"])
    west, north, step = float(d["xmin"]), float(d["ymin"]), float(d["dx"])
    profile = {
        "driver": "GTiff",
        "width": z.shape[1],
        "height": z.shape[0],
        "count": 1,
        "dtype": "int16",
        "crs": "EPSG:4326",
        "transform": from_origin(west, north, step, step),
        "nodata": -32768,
    }
    with rasterio.open(path, "w", **profile) as out:
        out.write(z.astype(np.int16), 1)
    return path
