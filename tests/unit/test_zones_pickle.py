"""A zone set is pickled once: every deliberation chunk and preview sent to a worker carries the set in force."""

from __future__ import annotations

import copy
import pickle

import numpy as np
import pytest

from pfp_service.core import zones as zones_mod
from pfp_service.core.zones import Zone, ZoneSet

pytestmark = pytest.mark.unit


def _set(n: int, x0: float = 0.0) -> ZoneSet:
    return ZoneSet(
        Zone.polygon(
            f"z{k}", [(x0 + 10 * k, 0), (x0 + 10 * k + 5, 0), (x0 + 10 * k + 5, 5), (x0 + 10 * k, 5)]
        )
        for k in range(n)
    )


def test_a_round_trip_gives_the_same_set_and_the_same_answers():
    zs = _set(12)
    back = pickle.loads(pickle.dumps(zs))
    assert back.ids == zs.ids and back.zones == zs.zones
    for a, b in zip(back.packed(), zs.packed(), strict=True):
        assert np.array_equal(a, b)
    assert back.search_margin_m == zs.search_margin_m
    pts = np.random.default_rng(1).uniform(-10, 130, size=(200, 2))
    assert np.array_equal(back.signed_distance(pts), zs.signed_distance(pts))
    assert back.zone_at(2.0, 2.0) == zs.zone_at(2.0, 2.0) == "z0"


def test_the_zones_are_pickled_at_the_first_pickling_only(monkeypatch):
    zs = _set(30)
    made = []
    real = pickle.dumps

    class Counting:
        HIGHEST_PROTOCOL = pickle.HIGHEST_PROTOCOL
        loads = staticmethod(pickle.loads)

        @staticmethod
        def dumps(obj, protocol=None):
            made.append(obj)
            return real(obj, protocol=protocol)

    monkeypatch.setattr(zones_mod, "pickle", Counting)
    first = pickle.dumps(zs)
    again = [pickle.dumps(zs) for _ in range(3)]
    assert len(made) == 1, "the zones were pickled again"
    assert all(a == first for a in again)


def test_copies_share_the_immutable_set():
    zs = _set(3)
    assert copy.copy(zs) is zs and copy.deepcopy(zs) is zs
    assert copy.deepcopy({"a": zs})["a"] is zs


def test_a_process_unpickles_the_same_bytes_once_and_keeps_a_few_sets():
    zones_mod._UNPICKLED.clear()
    sets = [_set(4, x0=1000.0 * k) for k in range(zones_mod._UNPICKLED_KEPT + 2)]
    blobs = [pickle.dumps(s) for s in sets]
    first = pickle.loads(blobs[0])
    assert pickle.loads(bytes(bytearray(blobs[0]))) is first  # the same bytes, another object: one set
    for b in blobs[1:]:
        pickle.loads(b)
    assert len(zones_mod._UNPICKLED) == zones_mod._UNPICKLED_KEPT
    assert pickle.loads(blobs[-1]).ids == sets[-1].ids
    assert pickle.loads(blobs[0]) is not first  # evicted: made again
