"""A load source for the map's scale test: N units' states and directions at R Hz, as a planner and fleet would.

Run as ``python -m tests.map_load ENDPOINT MISSION UNITS RATE_HZ SECONDS``; it
prints one JSON line with what it sent.  Units circle in a 1 km square with a
mix of statuses and five look-ahead points each, so every sample changes what
the map must draw.  Bounded: it stops by itself after SECONDS.
"""

from __future__ import annotations

import json
import math
import sys
import time

import zenoh

from pfp_service.wire import keys
from tests.zenoh_util import client

STATUSES = ("en_route", "en_route", "en_route", "escaping", "arrived", "trapped", "no_goal")


def main(endpoint: str, mission: str, units: int, rate_hz: float, seconds: float) -> dict[str, float]:
    enc = zenoh.Encoding.APPLICATION_JSON
    ids = [f"u{i}" for i in range(units)]
    state_keys = [keys.unit_state(mission, u) for u in ids]
    direction_keys = [keys.unit_direction(mission, u) for u in ids]
    sent = 0
    late = 0
    with client(endpoint) as s:
        start = time.monotonic()
        tick = 0
        while True:
            t = tick / rate_hz
            if t >= seconds:
                break
            for i, u in enumerate(ids):
                cx, cy = (i % 40) * 25.0, (i // 40) * 25.0
                a = 0.2 * t + i
                x, y = cx + 10 * math.cos(a), cy + 10 * math.sin(a)
                heading = (90.0 - math.degrees(a + math.pi / 2)) % 360.0
                state = {
                    "position": [x, y],
                    "seq": tick,
                    "kind": "manned" if i % 3 == 0 else "unmanned",
                    "speed_mps": 2.0,
                    "heading_deg": heading,
                }
                s.put(state_keys[i], json.dumps(state).encode(), encoding=enc)
                look = [
                    [cx + 10 * math.cos(a + 0.02 * k), cy + 10 * math.sin(a + 0.02 * k)] for k in range(1, 6)
                ]
                direction = {
                    "unit": u,
                    "seq": tick,
                    "status": STATUSES[i % len(STATUSES)],
                    "vector": [-math.sin(a), math.cos(a)],
                    "heading_deg": heading,
                    "distance_to_goal": 50.0,
                    "threat_level": 0.01,
                    "lookahead": look,
                }
                s.put(direction_keys[i], json.dumps(direction).encode(), encoding=enc)
                sent += 2
            tick += 1
            wait = start + tick / rate_hz - time.monotonic()
            if wait > 0:
                time.sleep(wait)
            else:
                late += 1
        elapsed = time.monotonic() - start
    return {
        "sent": sent,
        "elapsed_s": elapsed,
        "rate_per_s": sent / elapsed,
        "late_ticks": late,
        "ticks": tick,
    }


if __name__ == "__main__":
    ep, m, n, hz, secs = sys.argv[1:6]
    print(json.dumps(main(ep, m, int(n), float(hz), float(secs))), flush=True)
