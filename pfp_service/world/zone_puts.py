"""A keep-out zone put, removed or expired: what each puts in the world's batch (``Batch.zones``).

A zone put takes force at once, its box (and the box it replaces) listed
for the world to re-judge the units it reaches; one past ``max_zones``, or
one the engine cannot take, is refused on its key.  Pure values: ``now``
is the batch's.
"""

from __future__ import annotations

from pfp_service.errors import InputError
from pfp_service.wire import keys
from pfp_service.wire.messages import ZoneUpdate
from pfp_service.world import translate
from pfp_service.world.events import Batch
from pfp_service.world.threat_puts import Puts
from pfp_service.world.world_records import ZoneRecord

__all__ = ["ZonePuts"]


class ZonePuts(Puts):
    """The world's zone inputs."""

    def put(self, zid: str, msg: ZoneUpdate, b: Batch) -> None:
        """``msg`` put as zone ``zid``, or refused on its key."""
        s, kind = self.settings, keys.KeyKind.ZONE
        if zid not in self._rec.zones and len(self._rec.zones) >= s.max_zones:
            self._limits.overload += 1
            err = InputError("$", f"planner at max_zones ({s.max_zones})")
            self._reject(keys.zone(s.mission, zid), err, b, kind)
            return
        try:
            zone = translate.zone(msg, zid)
        except ValueError as exc:  # decoded, yet not a zone the engine takes: refused on its key
            self._reject(keys.zone(s.mission, zid), InputError("$", str(exc)), b, kind)
            return
        new = ZoneRecord(msg, zone, None if msg.ttl_s is None else b.now + msg.ttl_s)
        old = self._rec.put_zone(zid, new)
        if old is not None:
            b.zones.append((zid, "", old.zone.bounds()))
        b.zones.append((zid, "put", zone.bounds()))
        if new.expires_at is not None:
            self._timers.set(new.expires_at, "zone_expire", zid)

    @staticmethod
    def gone(z: ZoneRecord | None, zid: str, change: str, b: Batch) -> None:
        """Zone ``zid`` removed or expired (``z``: what it was; ``None``: there was none)."""
        if z is not None:
            b.zones.append((zid, change, z.zone.bounds()))
