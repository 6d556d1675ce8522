"""A route a deliberation worker found comes back as the same kernel types as one made here."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from pfp_service.core import steprule
from pfp_service.core.route import EscapeRun
from pfp_service.core.route_kernels import ahead_walk, steer_step

pytestmark = pytest.mark.unit


def test_an_unpickled_route_steers_without_compiling_its_kernels_again():
    unit = steprule.unit((30.0, 30.0), 0.0, 0.5, 1.0, None)
    here = EscapeRun.along("round", np.array([[0.0, 0.0], [20.0, 0.0], [20.0, 20.0]]), 1.0)
    here.steer(unit, 0.5, 0.2)
    assert here.ahead(unit, 0.5, 0.2, 4) is not None
    compiled = (len(steer_step.signatures), len(ahead_walk.signatures))
    there = pickle.loads(pickle.dumps(here))  # as a worker's answer arrives
    assert not there.path.flags.writeable and not there.segs.flags.writeable
    assert (there.cursor, there.name, there.n) == (here.cursor, here.name, here.n)
    assert there.steer(unit, 0.6, 0.2) is not None
    assert there.ahead(unit, 0.6, 0.2, 4) is not None
    # a writable array is another numba type: it would compile in the live loop, seconds on a cold cache
    assert (len(steer_step.signatures), len(ahead_walk.signatures)) == compiled
