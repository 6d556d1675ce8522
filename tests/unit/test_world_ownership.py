"""Cluster ownership (world/ownership.py): rendezvous hashing over the live planners, and the peers' debounce."""

from __future__ import annotations

import pytest

from pfp_service.wire import keys
from pfp_service.world.ownership import Ownership, rendezvous_weight, shard_owners

pytestmark = pytest.mark.unit

UNITS = [f"u{i}" for i in range(600)]


def _owned(planners: list[str]) -> dict[str, str]:
    """unit -> the planner that owns it, each planner asked for itself."""
    owners: dict[str, str] = {}
    for me in planners:
        own = Ownership(me, cluster=True)
        for p in planners:
            own.joined(p)
        owners |= {u: me for u in UNITS if own.owns(u)}
    return owners


def test_without_cluster_or_peers_a_planner_owns_every_unit():
    assert all(Ownership("p0", cluster=False).owns(u) for u in UNITS)
    alone = Ownership("p0", cluster=True)
    assert all(alone.owns(u) for u in UNITS)
    solo = Ownership("p0", cluster=False)
    solo.joined("p1")
    assert all(solo.owns(u) for u in UNITS)  # not a cluster: a peer is a conflict, not an owner


def test_every_unit_has_exactly_one_owner_and_the_share_is_fair():
    planners = ["p0", "p1", "p2"]
    owners = _owned(planners)
    assert set(owners) == set(UNITS)  # each planner decides alone, and they agree
    for p in planners:  # 16 shards over 3: 6, 6 and 4 (bounded load), each about 37.5 units
        assert 100 < sum(o == p for o in owners.values()) < 280


@pytest.mark.parametrize(
    "planners", [["p0", "p1"], ["a", "b"], ["planner-1", "planner-2"], ["x", "y", "z", "w"]]
)
def test_shards_are_shared_evenly_and_a_unit_is_owned_with_its_shard(planners):
    owners = shard_owners(set(planners))
    counts = [owners.count(p) for p in planners]
    assert max(counts) - min(counts) <= 1 and sum(counts) == keys.SHARDS
    owned = _owned(planners)
    for u in UNITS:
        assert owned[u] == owners[keys.shard_of(u)]
    for p in planners:  # about 1/K of the units each (shards even; units over shards by CRC-32)
        assert abs(sum(o == p for o in owned.values()) / len(UNITS) - 1 / len(planners)) < 0.05
    me = Ownership(planners[0], cluster=True)
    for p in planners:
        me.joined(p)
    assert me.shards() == frozenset(s for s, p in enumerate(owners) if p == planners[0])


def test_a_planner_joining_takes_units_only_for_itself_and_one_leaving_hands_over_only_its_own():
    before, after = _owned(["p0", "p1"]), _owned(["p0", "p1", "p2"])
    moved = {u for u in UNITS if before[u] != after[u]}
    assert moved and all(after[u] == "p2" for u in moved)  # here bounded load moved nothing else
    assert 120 < len(moved) < 280  # about a third
    gone = _owned(["p0", "p2"])
    kept = [u for u in UNITS if after[u] != "p1"]
    assert sum(gone[u] == after[u] for u in kept) >= 0.8 * len(kept)  # bounded load may move a shard more


def test_weights_are_a_pure_function_of_unit_and_planner():
    assert rendezvous_weight("u1", "p0") == rendezvous_weight("u1", "p0")
    assert rendezvous_weight("u1", "p0") != rendezvous_weight("u1", "p1")
    assert all(0 <= rendezvous_weight(u, "p0") < 2**64 for u in UNITS)
    assert len({rendezvous_weight(u, "p0") for u in UNITS}) == len(UNITS)


def test_a_peer_gone_counts_only_after_the_debounce_and_one_back_within_it_never_moved():
    own = Ownership("me", cluster=True)
    assert own.joined("p1") and not own.joined("p1") and not own.joined("me")
    assert own.left("p1", 10.0) and not own.left("p1", 10.5)  # one debounce per going
    assert not own.settle("p1", 11.0, debounce_s=2.0)  # not yet
    assert not own.joined("p1")  # back within the debounce: not new, and its debounce is over
    assert not own.settle("p1", 12.0, debounce_s=2.0) and own.peers == {"p1"}
    assert own.left("p1", 20.0) and own.settle("p1", 22.0, debounce_s=2.0)
    assert own.peers == set() and own.joined("p1")  # a new peer again


def test_an_unknown_planner_going_starts_no_debounce():
    own = Ownership("me", cluster=True)
    assert not own.left("stranger", 0.0) and own.gone == {}


def test_a_preview_is_answered_by_the_units_owner_alone():
    from pfp_service.world.world import PeerPlanner, World, WorldSettings

    worlds = {p: World(WorldSettings(planner_id=p, cluster=True)) for p in ("p0", "p1")}
    for me, w in worlds.items():
        w.apply([PeerPlanner("p1" if me == "p0" else "p0", True)], 0.0)
    for u in UNITS[:50]:
        answering = [p for p, w in worlds.items() if w.preview(u) is not None]
        assert len(answering) == 1 and worlds[answering[0]].owns(u)
    assert World().preview("anyone") is not None  # alone, a planner answers every preview
