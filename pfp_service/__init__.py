"""pfp-service: real-time potential-field path planning for manned-unmanned teams."""

import os as _os

# numba's parallel kernels run on OpenMP here; libgomp's threads spin for a while after
# every parallel region, taking the planning loop's core on a 2-core machine (docs/operations.md,
# "Figures behind the code's choices").  Passive waiting, unless the user says.
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")


def _numba_cache_dir(root: str | None = None) -> str | None:
    """Where numba keeps this tree's compiled kernels: one directory per version of their sources.

    numba checks a cached kernel against its own file's time stamp only, so a kernel that inlined
    a function from another module (``core.kernels`` into ``core.steprule``, say) is loaded stale
    after that other file alone changes: a checkout pulled, or a branch merged, planned with the
    old code.  Keyed by a hash of every compiled module's source, a change to any of them compiles
    afresh.  A few milliseconds at import (about 40 files); ``NUMBA_CACHE_DIR`` set by the user wins.
    """
    import hashlib
    from pathlib import Path

    here = Path(root) if root is not None else Path(__file__).resolve().parent
    digest = hashlib.blake2b(digest_size=8)
    try:
        for sub in ("core", "terrain"):
            for path in sorted((here / sub).glob("*.py")):
                digest.update(path.name.encode())
                digest.update(path.read_bytes())
    except OSError:  # sources unreadable: numba's own default
        return None
    return str(here / "__pycache__" / f"numba-{digest.hexdigest()}")


if "NUMBA_CACHE_DIR" not in _os.environ and (_cache := _numba_cache_dir()) is not None:
    _os.environ["NUMBA_CACHE_DIR"] = _cache  # read by numba when it is first imported, after this

__version__ = "0.1.0"
__all__ = ["__version__"]
