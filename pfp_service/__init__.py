"""pfp-service: real-time potential-field path planning for manned-unmanned teams."""

import os as _os

# numba's parallel kernels run on OpenMP here; libgomp's threads spin for a while after
# every parallel region, taking the planning loop's core on a 2-core machine (measured:
# list conversions after a parallel tick 5x slower).  Passive waiting, unless the user says.
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

__version__ = "0.1.0"
__all__ = ["__version__"]
