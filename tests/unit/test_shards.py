"""State shards (wire/keys.py): the shard function's test vectors, the shard key, and what it refuses."""

from __future__ import annotations

import zlib

import pytest

from pfp_service.errors import InputError
from pfp_service.wire import keys
from pfp_service.wire.keys import Key, KeyKind

pytestmark = pytest.mark.unit

# The vectors docs/wire.md and schemas/README.md give an outside client: CRC-32 of the UTF-8 id, mod 16.
VECTORS = {"ugv-1": 15, "u0": 0, "u1": 6, "tank-2": zlib.crc32(b"tank-2") % 16}


@pytest.mark.parametrize(("unit", "shard"), VECTORS.items())
def test_shard_of_matches_the_published_vectors(unit: str, shard: int) -> None:
    assert keys.SHARDS == 16
    assert keys.shard_of(unit) == shard
    assert keys.shard_state("m1", unit) == f"mumt/m1/shard/{shard}/unit/{unit}/state"


def test_shards_spread_units_evenly() -> None:
    counts = [0] * keys.SHARDS
    for i in range(16_000):
        counts[keys.shard_of(f"unit-{i}")] += 1
    assert min(counts) > 800 and max(counts) < 1200


def test_a_shard_key_parses_as_the_units_state() -> None:
    key = keys.shard_state("m1", "ugv-1")
    assert keys.parse(key) == Key(KeyKind.UNIT_STATE, "m1", "ugv-1")
    assert keys.KeyOf(KeyKind.UNIT_STATE, "m1").id(key) == "ugv-1"
    assert keys.KeyOf(KeyKind.UNIT_STATE, "m1").id("mumt/m1/unit/ugv-1/state") == "ugv-1"
    assert keys.shard_states("m1", 3) == "mumt/m1/shard/3/unit/*/state"
    assert keys.sharded_states("m1") == "mumt/m1/shard/*/unit/*/state"
    assert keys.unit_states_any("m1") == "mumt/m1/**/unit/*/state"


@pytest.mark.parametrize(
    ("key", "why"),
    [
        ("mumt/m1/shard/3/unit/ugv-1/state", "in shard 15, not 3"),  # the wrong shard for the unit
        ("mumt/m1/shard/15/unit/a b/state", "chunk"),
        ("mumt/m1/shard/015/unit/ugv-1/state", "not a key"),  # one spelling of a shard only
        ("mumt/m1/shard/x/unit/ugv-1/state", "not a key"),
    ],
)
def test_a_bad_shard_key_is_refused_with_its_reason(key: str, why: str) -> None:
    with pytest.raises(InputError) as e:
        keys.parse(key)
    assert e.value.path == "key" and why in e.value.reason
    with pytest.raises(InputError):
        keys.KeyOf(KeyKind.UNIT_STATE, "m1").id(key)


def test_a_shard_key_of_another_mission_is_not_this_ones() -> None:
    with pytest.raises(InputError, match="mission 'm2'"):
        keys.KeyOf(KeyKind.UNIT_STATE, "m1").id(keys.shard_state("m2", "u1"))
    with pytest.raises(InputError):
        keys.shard_states("m1", keys.SHARDS)
