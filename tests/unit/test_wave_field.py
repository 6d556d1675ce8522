"""The world's field from packed rows kept per threat (``Records.field``): the same bytes as packing every threat again."""

from __future__ import annotations

import numpy as np
import pytest

from pfp_service.core import ThreatField
from pfp_service.core.cull import MIN_THREATS
from pfp_service.wire import ThreatUpdate
from pfp_service.world import translate
from pfp_service.world.world_records import Records, ThreatRecord

pytestmark = pytest.mark.unit


def _threat(tid: str, x: float, y: float = 0.0, skew: float = 2.0) -> ThreatRecord:
    u = ThreatUpdate(position=(x, y), facing_deg=40.0, sigma_range=3.0, sigma_lateral=1.5, skew=skew)
    return ThreatRecord(u, translate.threat(u, tid), None)


def _fresh(r: Records) -> ThreatField:
    return ThreatField([r.threats[k].threat for k in sorted(r.threats)], r.intensity)  # type: ignore[arg-type]


@pytest.mark.parametrize("intensity", ["peak", "density"])
def test_the_field_from_kept_rows_is_the_field_packed_afresh_through_puts_moves_and_removals(intensity):
    r = Records(intensity)
    for i in range(MIN_THREATS + 3):  # a cull index too
        r.put_threat(f"t{i:02d}", _threat(f"t{i:02d}", 10.0 * i, skew=0.5 * (i % 5)))
    steps = [
        lambda: None,
        lambda: r.put_threat("t05", _threat("t05", -40.0, 7.0)),  # moved: its row packed again
        lambda: r.put_threat("a-new", _threat("a-new", 3.0, 3.0)),  # first in id order
        lambda: r.remove_threat("t10"),
        lambda: r.put_threat("zz", _threat("zz", 1.0, -9.0, skew=0.0)),
    ]
    for step in steps:
        step()
        got, want = r.field, _fresh(r)
        assert got.packed.tobytes() == want.packed.tobytes()
        assert got.positions.tobytes() == want.positions.tobytes()
        assert got.threats == want.threats and got.intensity == want.intensity == intensity
        assert r.cull is not None and r.cull.packed is got.packed
        at = np.array([[5.0, 1.0]])
        assert got.level(at).tobytes() == want.level(at).tobytes()


def test_a_threat_put_again_is_packed_again_and_the_others_keep_their_rows():
    r = Records()
    r.put_threat("a", _threat("a", 0.0))
    r.put_threat("b", _threat("b", 20.0))
    _ = r.field
    kept = r.threats["a"].row
    assert kept is not None
    r.put_threat("b", _threat("b", 30.0))
    assert r.threats["b"].row is None  # the new record: packed when the field is asked
    fld = r.field
    assert r.threats["a"].row is kept and fld.packed[1, 0] == 30.0


def test_an_empty_field():
    r = Records()
    assert len(r.field) == 0 and r.field.packed.shape == _fresh(r).packed.shape
