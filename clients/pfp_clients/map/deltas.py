"""Two of the map's deltas as one, for a browser that has not taken the first yet (``merge_deltas``)."""

from __future__ import annotations

from typing import Any

__all__ = ["merge_deltas"]

# the kinds a delta puts by id and removes by id, besides the units (whose tracks add up)
_KEYED = ("threats", "zones", "teams")


def _keyed(old: dict[str, Any], new: dict[str, Any], name: str) -> tuple[dict[str, Any], list[str]]:
    """A kind's views and removals over both deltas: a put after a removal cancels it, and back."""
    views = dict(old.get(name, {}))
    removed = set(old.get(f"{name}_removed", ()))
    for i, view in new.get(name, {}).items():
        views[i] = view
        removed.discard(i)
    for i in new.get(f"{name}_removed", ()):
        views.pop(i, None)
        removed.add(i)
    return views, sorted(removed)


def merge_deltas(
    old: dict[str, Any] | None, new: dict[str, Any], track_max: int = 200, events_max: int = 100
) -> dict[str, Any]:
    """One delta saying what ``old`` then ``new`` say, for a browser that has not taken ``old`` yet.

    A unit's, threat's, zone's or team's newer view wins, but a unit's new track points add up;
    a put after a removal cancels it and a removal after a put drops the put, so
    an id is never both shown and removed.  Events add up to ``events_max``.
    """
    if old is None:
        return new
    out = dict(old)
    out["now"] = new["now"]
    units = dict(old.get("units", {}))
    removed_units = set(old.get("units_removed", ()))
    for uid, view in new.get("units", {}).items():
        prior = units.get(uid)
        if prior is not None:
            view = {**view, "track_add": (prior["track_add"] + view["track_add"])[-track_max:]}
        units[uid] = view
        removed_units.discard(uid)
    for uid in new.get("units_removed", ()):
        units.pop(uid, None)
        removed_units.add(uid)
    merged: list[tuple[str, Any]] = [("units", units), ("units_removed", sorted(removed_units))]
    for name in _KEYED:
        views, removed = _keyed(old, new, name)
        merged += [(name, views), (f"{name}_removed", removed)]
    merged += [
        ("events", (old.get("events", []) + new.get("events", []))[-events_max:]),
        ("rejected", {**old.get("rejected", {}), **new.get("rejected", {})}),
        ("status", {**old.get("status", {}), **new.get("status", {})}),
    ]
    for name, value in merged:
        if value:
            out[name] = value
        else:
            out.pop(name, None)
    return out
