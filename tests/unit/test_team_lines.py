"""A lead's track grown in place (``team_lines.grow``) is the very line ``Polyline`` makes of the whole track.

Compared bit for bit with ``Polyline(track)`` and with ``Polyline.extended`` (the code it replaced in the
team book) along seeded tracks grown a point or a few at a time, past the arrays' room, with segments of
no length, a line from elsewhere handed in (the arrays then made afresh), and the lines handed out before
checked unchanged by the rows written after them.
"""

from __future__ import annotations

import random

import numpy as np
import pytest

from pfp_service.world import team_lines
from pfp_service.world.polyline import Polyline
from pfp_service.world.team_book import TeamBook

pytestmark = pytest.mark.unit

FIELDS = ("pts", "ab", "seg", "sq", "cum")


def _same(a: Polyline, b: Polyline) -> bool:
    return all(
        getattr(a, f).shape == getattr(b, f).shape and np.array_equal(getattr(a, f), getattr(b, f))
        for f in FIELDS
    )


def _copy(line: Polyline) -> dict[str, np.ndarray]:
    return {f: getattr(line, f).copy() for f in FIELDS}


@pytest.mark.parametrize("seed", range(30))
def test_a_track_grown_in_place_is_the_polyline_of_the_whole_track(seed: int) -> None:
    rng = random.Random(seed)
    print(f"seed {seed}")
    track: list[tuple[float, float]] = [(rng.uniform(-1e4, 1e4), rng.uniform(-1e4, 1e4))]
    line, grown = Polyline(track), None
    plain = Polyline(track)
    handed: list[tuple[Polyline, dict[str, np.ndarray]]] = []
    for _ in range(rng.randint(20, 300)):
        more = []
        for _ in range(rng.choice([0, 1, 1, 1, 2, 5])):
            x, y = track[-1] if not more else more[-1]
            if rng.random() < 0.1:
                more.append((x, y))  # a segment of no length
            else:
                more.append((x + rng.gauss(0.0, 3.0), y + rng.gauss(0.0, 3.0) * rng.choice([1.0, 1e-9])))
        track += more
        if rng.random() < 0.05:  # another line for the same track (another code's, or made afresh)
            line = Polyline(track[: len(line.pts)])
        line, grown = team_lines.grow(grown, line, more)
        plain = plain.extended(more)
        assert _same(line, plain), seed
        assert _same(line, Polyline(track)), seed
        handed.append((line, _copy(line)))
    for old, numbers in handed:  # rows written after a line was handed out are not in it
        assert all(np.array_equal(getattr(old, f), numbers[f]) for f in FIELDS)


def test_an_empty_line_and_nothing_more_are_as_extended() -> None:
    empty = Polyline([])
    got, grown = team_lines.grow(None, empty, [(1.0, 2.0), (3.0, 4.0)])
    assert grown is None and _same(got, empty.extended([(1.0, 2.0), (3.0, 4.0)]))
    one = Polyline([(0.0, 0.0)])
    assert team_lines.grow(None, one, []) == (one, None)


def test_the_books_line_follows_its_track_grown_trimmed_and_replaced() -> None:
    book = TeamBook()
    rng = random.Random(7)
    book.tracks["t"] = track = [(0.0, 0.0)]
    for step in range(400):
        if step == 150:  # trimmed: another list
            book.tracks["t"] = track = track[100:]
        if step == 300:  # a new lead
            book.tracks["t"] = track = []
        track.append((rng.uniform(0, 1e3), rng.uniform(0, 1e3)))
        if rng.random() < 0.7:  # not every point is seen by a follower
            assert _same(book._line("t"), Polyline(track)), step


def test_the_arrays_hold_no_more_than_the_longest_track_kept() -> None:
    from pfp_service.world.team_tracks import MAX_TRACK_POINTS

    track = [(float(k), 0.0) for k in range(MAX_TRACK_POINTS - 10)]
    line, grown = team_lines.grow(None, Polyline(track[:-1]), track[-1:])
    assert grown is not None and len(grown.pts) == MAX_TRACK_POINTS
    more = [(float(k), 1.0) for k in range(20)]  # past it (a track is trimmed before): room made for them
    line, grown = team_lines.grow(grown, line, more)
    assert grown is not None and len(grown.pts) >= len(track) + 20
    assert _same(line, Polyline(track + more))
