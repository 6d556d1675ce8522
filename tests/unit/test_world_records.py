"""The world's records (world/world_records.py): threats and zones, and the field (units: test_world_units.py)."""

from __future__ import annotations

import pytest

from pfp_service.wire import ThreatUpdate
from pfp_service.world import translate
from pfp_service.world.world_records import Records, ThreatRecord

pytestmark = pytest.mark.unit


def _threat(tid: str, x: float, expires: float | None = None) -> ThreatRecord:
    u = ThreatUpdate(position=(x, 0.0), sigma_range=1.0, sigma_lateral=0.7)
    return ThreatRecord(u, translate.threat(u, tid), expires)


def test_the_field_is_rebuilt_only_when_the_threats_change():
    r = Records("density")
    assert len(r.field) == 0
    r.put_threat("t1", _threat("t1", 1.0))
    f1 = r.field
    assert len(f1) == 1 and r.field is f1  # cached while the threats stand
    old = r.put_threat("t1", _threat("t1", 2.0))
    assert old is not None and old.update.position == (1.0, 0.0)
    assert r.field is not f1 and r.field.threats[0].xi[0] == 2.0
    assert r.remove_threat("t1") is not None and len(r.field) == 0
    assert r.remove_threat("t1") is None


def test_a_threat_expires_only_if_its_ttl_has_run_out():
    r = Records()
    r.put_threat("t", _threat("t", 0.0, expires=10.0))
    assert r.expire("t", 9.0) is None and "t" in r.threats
    r.put_threat("t", _threat("t", 0.0, expires=20.0))  # put again: the old timer finds it fresh
    assert r.expire("t", 10.0) is None
    assert r.expire("t", 20.0) is not None and r.threats == {}
    r.put_threat("forever", _threat("forever", 0.0))
    assert r.expire("forever", 1e12) is None
