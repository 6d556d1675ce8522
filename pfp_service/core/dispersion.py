"""Dispersion: the repulsive term between friendly units, its exact gradient, and the neighbour index.

Unit ``i`` at ``p`` feels each friendly unit ``j`` at ``q_j`` within the
pair's reach ``rho_ij = REACH * s_ij`` (``s_ij`` the pair's separation)
through the potential

    phi_i(p) = sum_j (rho_ij / 2) (1 - d_ij / rho_ij)^2,   d_ij = |p - q_j| < rho_ij

whose gradient is exact and closed-form:

    grad phi_i(p) = - sum_j (1 - d_ij / rho_ij) (p - q_j) / d_ij

Each pair's share of it is at most 1 (dimensionless), so the world weighs
it against the field the unit descends as the zone barrier is weighed
(``steprule``): ``PUSH * |grad f|`` where the unit stands, frozen for the
step.  A unit descending ``f + PUSH |grad f| phi`` straight at a neighbour
that stands still stops where ``PUSH (1 - d / rho) = 1``, that is at
``d = rho (1 - 1 / PUSH)`` (``4/3 s`` with the defaults): a third outside
the separation, so a crowd's jostling keeps clear of it.  Two units on the
very same point have no gradient between them; the one of lower index is
pushed west, the other east, so they part.

A pair's separation (``pair_separation``) is the larger of its two
units' (by class), or their team's ``separation_m`` when both are in one
team that sets it; and near a shared goal it relaxes: a pair whose goals
are closer than ``1 / RELAX`` separations could never both arrive, so as
the farther of the two from its goal comes within ``RELAX_OVER``
separations of it, the pair's separation shrinks linearly towards
``RELAX`` times the gap between their goals (never below it, never above
the separation).  At their goals the two then stand outside each other's
stopping distance (``4/3 RELAX < 1`` of the goals' gap).

``NeighbourIndex`` is a ``scipy.spatial.cKDTree`` over every unit's
position, built once per tick; the pairs within reach of the units being
advised are found in compiled code (``query_ball_point`` for a few of them,
``query_pairs`` once for many) and ``gradients`` sums them.  ``brute_gradients`` is the ``O(N^2)`` reference the tests hold it to.
The index's few rows' neighbours on a kept tree, its pairs' separations and
their gradient terms are compiled (``neighbour_kernels``: a live tick asks
for a few units, where NumPy's call cost was most of it); ``pair_separation``
and ``_pair_terms`` are the NumPy they are held to, bit for bit, and what
``brute_gradients`` sums.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import numpy as np
from scipy.spatial import cKDTree

from pfp_service.core import neighbour_kernels as kernels

__all__ = [
    "PUSH",
    "REACH",
    "RELAX",
    "RELAX_OVER",
    "NeighbourIndex",
    "brute_gradients",
    "gradient",
    "pair_separation",
    "potential",
]

REACH = 2.0  # a neighbour is felt within this many separations
PUSH = 3.0  # the term's weight in units of the field's own slope where the unit stands
RELAX = 0.6  # near a shared goal a pair keeps at least this share of its goals' gap (4/3 of it < 1)
RELAX_OVER = 2.0  # ... relaxing as the farther of the two comes within this many separations of its goal
FEW_ROWS = 4  # ``near`` queries its rows alone while they are under a quarter of the units
# an index with a few units moved keeps its k-d tree while no unit is further than this share of the reach from
# where the tree holds it, each query widened by that distance and its answers measured at the units' positions
STALE_SHARE = 0.25
_NO = (np.zeros(0, dtype=np.intp), np.zeros(0))  # no teams, for ``neighbour_kernels.pair_seps``
_NO_GOALS = np.zeros((0, 2))


def potential(p: np.ndarray, q: np.ndarray, rho: np.ndarray) -> float:
    """``phi(p)`` from neighbours ``q`` (``(M, 2)``) with reaches ``rho`` (``(M,)``), in metres."""
    d = np.hypot(p[0] - q[:, 0], p[1] - q[:, 1])
    near = d < rho
    return float(np.sum(0.5 * rho[near] * (1.0 - d[near] / rho[near]) ** 2))


def gradient(p: np.ndarray, q: np.ndarray, rho: np.ndarray) -> np.ndarray:
    """``grad phi(p)``, exact, from neighbours ``q`` with reaches ``rho``; a coincident neighbour adds nothing."""
    dx, dy = p[0] - q[:, 0], p[1] - q[:, 1]
    d = np.hypot(dx, dy)
    near = (d < rho) & (d > 0.0)
    w = np.where(near, (1.0 - d / rho) / np.where(near, d, 1.0), 0.0)
    return np.array([-np.sum(w * dx), -np.sum(w * dy)])


def pair_separation(
    points: np.ndarray,
    seps: np.ndarray,
    i: np.ndarray,
    j: np.ndarray,
    team: np.ndarray | None = None,
    team_sep: np.ndarray | None = None,
    goals: np.ndarray | None = None,
) -> np.ndarray:
    """Each pair ``(i, j)``'s separation in metres: by class, by team, relaxed near a shared goal.

    Args:
        points: ``(N, 2)`` positions.
        seps: ``(N,)`` each unit's separation by its class (a pair keeps the larger).
        i, j: the pairs, as rows.
        team: ``(N,)`` each unit's team as a number, ``-1`` for none; a pair in one team keeps ...
        team_sep: ``(N,)`` ... its team's separation instead.
        goals: ``(N, 2)`` each unit's goal, NaN for none: a pair with both relaxes near them.
    """
    s = np.maximum(seps[i], seps[j])
    if team is not None and team_sep is not None:
        s = np.where((team[i] == team[j]) & (team[i] >= 0), team_sep[i], s)
    if goals is not None:
        gap = np.hypot(goals[i, 0] - goals[j, 0], goals[i, 1] - goals[j, 1])  # NaN without both goals
        far = np.maximum(
            np.hypot(points[i, 0] - goals[i, 0], points[i, 1] - goals[i, 1]),
            np.hypot(points[j, 0] - goals[j, 0], points[j, 1] - goals[j, 1]),
        )
        floor = np.minimum(s, RELAX * gap)
        relaxed = floor + (s - floor) * np.minimum(far / (RELAX_OVER * s), 1.0)
        s = np.where(np.isfinite(relaxed), relaxed, s)
    return np.asarray(s, dtype=np.float64)


def _pair_terms(
    points: np.ndarray, pair_s: np.ndarray, i: np.ndarray, j: np.ndarray, n: int
) -> tuple[np.ndarray, np.ndarray]:
    """Sum over pairs ``(i, j)`` (``i`` the row; ``pair_s`` their separations) of each pair's gradient share."""
    keep = i != j
    i, j, pair_s = i[keep], j[keep], pair_s[keep]
    dx = points[i, 0] - points[j, 0]
    dy = points[i, 1] - points[j, 1]
    d = np.hypot(dx, dy)
    rho = REACH * pair_s
    near = d < rho
    i, j, dx, dy, d, rho = i[near], j[near], dx[near], dy[near], d[near], rho[near]
    same = d == 0.0
    w = (1.0 - d / rho) / np.where(same, 1.0, d)
    gx = -w * dx
    gy = -w * dy
    gx[same] = np.where(i[same] < j[same], 1.0, -1.0)  # -grad: the lower index goes west
    gy[same] = 0.0
    return np.bincount(i, gx, minlength=n), np.bincount(i, gy, minlength=n)


class NeighbourIndex:
    """Every unit's position and separation, with a k-d tree over them: built once per tick.

    Args:
        points: ``(N, 2)`` positions in metres.
        seps: ``(N,)`` each unit's separation in metres (a pair keeps the larger).
        team, team_sep, goals: as ``pair_separation``'s (``None``: no teams, no goals).
        moved_from: an index of the same units with the same separations, some of them elsewhere: its k-d
            tree is kept while every unit is within ``STALE_SHARE`` of the reach of where the tree holds it
            (a live tick moves a few units, and a tree over 1,000 took 234 us to build against 63 us for
            16 queries: BENCHMARKS.md, "The k-d tree kept"); the same neighbours either way.
        moved: with ``moved_from``, the rows whose points may differ from its (every other row's is its very
            point): only theirs are measured for the slack, and its separations, when the very arrays, are
            not searched for the widest again.  A micro-optimisation (bench row: BENCHMARKS.md "A tick's
            fixed cost"): a live tick moves a few of the fleet's rows.
    """

    def __init__(
        self,
        points: np.ndarray,
        seps: np.ndarray,
        team: np.ndarray | None = None,
        team_sep: np.ndarray | None = None,
        goals: np.ndarray | None = None,
        moved_from: NeighbourIndex | None = None,
        moved: Sequence[int] | None = None,
    ) -> None:
        self.seps: np.ndarray
        self.radius: float
        self.team_sep: np.ndarray | None
        was = moved_from
        if was is not None and seps is was.seps and team_sep is was.team_sep:  # the very arrays: their widest
            self.seps, self.radius = was.seps, was.radius
        else:
            self.seps = np.asarray(seps, dtype=np.float64).reshape(-1)
            widest = max(
                float(self.seps.max()),
                float(np.nanmax(team_sep, initial=0.0)) if team_sep is not None else 0.0,
            )
            self.radius = REACH * widest if len(self.seps) else 0.0
        self.points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
        self.team, self.team_sep, self.goals = team, team_sep, goals
        # the tree, the points it was built on, how far any unit is from its point there (0: built on these)
        # and each unit's squared distance from it
        self.tree, self._treed, self._slack, self._d2 = self._tree(moved_from, moved)
        self._pairs: tuple[np.ndarray, np.ndarray] | None = None
        self._near: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # the last ``near``: rows, i, j
        self._near_s: np.ndarray | None = None  # the separations of its pairs, once asked for
        # row -> its neighbours, as ``query_ball_point`` found them (``_found``)
        self._rows_found: dict[int, list[int]] = {}

    def _tree(
        self, moved_from: NeighbourIndex | None, moved: Sequence[int] | None
    ) -> tuple[cKDTree | None, np.ndarray, float, np.ndarray]:
        if not len(self.points):
            return None, self.points, 0.0, np.zeros(0)
        was = moved_from
        if (
            was is not None
            and was.tree is not None
            and was.radius == self.radius
            and len(was.points) == len(self.points)
        ):
            if moved is not None:  # the other rows' points are ``was``'s: their distances are its
                d2 = was._d2.copy()
                if len(moved):
                    d = self.points[moved] - was._treed[moved]
                    d2[moved] = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]
            else:
                d = self.points - was._treed
                d2 = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]
            slack = float(np.sqrt(np.max(d2)))
            if slack <= STALE_SHARE * self.radius:
                return was.tree, was._treed, slack, d2
        return cKDTree(self.points), self.points, 0.0, np.zeros(len(self.points))

    def unasked(self) -> NeighbourIndex:
        """This index as new-built: no ``near`` query remembered, so the next is asked afresh (and its pairs
        come in the order a new index would give them); the fleet's pairs, the same either way, are kept."""
        self._near, self._near_s = None, None
        return self

    def pair_seps(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """The separation of each pair ``(i, j)`` (``pair_separation``) in metres: its numbers, compiled
        (``neighbour_kernels.pair_seps``)."""
        i, j = np.asarray(i, dtype=np.intp).reshape(-1), np.asarray(j, dtype=np.intp).reshape(-1)
        out = np.empty(len(i))
        team, team_sep = (
            (self.team, self.team_sep) if self.team is not None and self.team_sep is not None else _NO
        )
        goals = self.goals if self.goals is not None else _NO_GOALS
        kernels.pair_seps(self.points, self.seps, i, j, team, team_sep, goals, RELAX, RELAX_OVER, out)
        return out

    def pairs(self) -> tuple[np.ndarray, np.ndarray]:
        """Every ordered pair ``(i, j)``, ``i != j``, within the widest reach: one compiled query, kept."""
        if self._pairs is None:
            if self.tree is None:
                none = np.zeros(0, np.intp)
                self._pairs = (none, none)
            else:  # a tree kept from other points is built afresh here: the fleet's pairs come in its order
                tree = self.tree if not self._slack else cKDTree(self.points)
                ij = tree.query_pairs(self.radius, output_type="ndarray").astype(np.intp)
                self._pairs = (np.concatenate([ij[:, 0], ij[:, 1]]), np.concatenate([ij[:, 1], ij[:, 0]]))
        return self._pairs

    def near(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Candidate pairs ``(i, j)`` for the units at ``rows``: every other ``j`` within the widest reach of ``i``.

        A few rows (a live tick's reports) are queried on their own, so a tick
        costs what it advises, not every pair of the fleet; many take the
        fleet's pairs, found once.  Either way the same pairs.  Rows among
        those of the last query (the tick's moving units after its advised
        ones) take that query's pairs.
        """
        i, j, _keep = self._near_rows(rows)
        return i, j

    def near_seps(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``near``'s pairs with their separations (``pair_seps``): those of the last query's pairs
        computed once for the tick's later callers (elementwise, so a subset's are the same numbers)."""
        i, j, keep = self._near_rows(rows)
        if self._near_s is None:
            last = self._near
            assert last is not None
            self._near_s = self.pair_seps(last[1], last[2])
        return i, j, self._near_s if keep is None else self._near_s[keep]

    def _near_rows(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """``near``'s pairs, and which of the last query's they are (``None``: all, a new query)."""
        rows = np.unique(np.asarray(rows, dtype=np.intp))
        last = self._near
        # whether every row was among the last query's: a mask over the fleet, not ``np.isin`` (which sorts
        # both; a micro-optimisation, bench row: ``python -m benchmarks._march_world``, the wave)
        if last is not None and _among(rows, last[0], len(self.points)):
            wanted = np.zeros(len(self.points), dtype=bool)
            wanted[rows] = True
            keep = wanted[last[1]]
            return last[1][keep], last[2][keep], keep
        if self.tree is None or len(rows) * FEW_ROWS >= len(self.points):
            i, j = _kept(*self.pairs(), rows, len(self.points))
        else:
            found = self._found(rows)
            counts = np.fromiter((len(f) for f in found), dtype=np.intp, count=len(rows))
            j = np.fromiter(itertools.chain.from_iterable(found), dtype=np.intp, count=int(counts.sum()))
            i = np.repeat(rows, counts)
            other = i != j
            i, j = i[other], j[other]
        self._near, self._near_s = (rows, i, j), None
        return i, j, None

    def _found(self, rows: np.ndarray) -> list[list[int]]:
        """Each row's neighbours within the widest reach, sorted (``query_ball_point``), each row queried
        once in this index's life: a row's answer depends on nothing but the points, so a wave's later
        shares (the same index, ``unasked``) take those its earlier ones found.  A micro-optimisation
        (bench row: ``python -m benchmarks._march_world``, the wave)."""
        memo, tree = self._rows_found, self.tree
        assert tree is not None
        wanted = rows.tolist()
        new = [r for r in wanted if r not in memo]
        if new:
            memo.update(zip(new, self._measured(new) if self._slack else self._asked(tree, new)))
        return [memo[r] for r in wanted]

    def _asked(self, tree: cKDTree, rows: list[int]) -> list[list[int]]:
        """The tree's own answers: built on these points."""
        got: list[list[int]] = tree.query_ball_point(self.points[rows], self.radius, return_sorted=True)
        return got

    def _measured(self, rows: list[int]) -> list[list[int]]:
        """A kept tree's answers (widened by its slack) measured at the units' positions with the tree's test
        (the squared distance at most the squared reach): that test over every point, one compiled pass
        (``neighbour_kernels.within``; the same neighbours in the same order, without the tree's widened
        query and a list per row measured apart).  A micro-optimisation (bench row: BENCHMARKS.md "A
        tick's fixed cost", ``python -m benchmarks._march_world --tick 4``)."""
        found = np.empty(len(rows) * len(self.points), dtype=np.intp)
        counts = np.empty(len(rows), dtype=np.intp)
        asked = np.asarray(rows, dtype=np.intp)
        got = kernels.within(self.points, asked, self.radius * self.radius, found, counts)
        flat, out, at = found[:got].tolist(), [], 0
        for c in counts.tolist():
            out.append(flat[at : at + c])
            at += c
        return out

    def gradients(self, rows: np.ndarray) -> np.ndarray:
        """``grad phi`` for the units at ``rows`` (indices into ``points``): ``(len(rows), 2)``."""
        rows = np.asarray(rows, dtype=np.intp)
        i, j, pair_s = self.near_seps(rows)
        # ``_pair_terms``, compiled (``neighbour_kernels.pair_terms``): the same sums in the same order
        g = np.zeros((len(self.points), 2))
        kernels.pair_terms(self.points, pair_s, i, j, REACH, g)
        got: np.ndarray = g[rows]
        return got


def _among(rows: np.ndarray, asked: np.ndarray, n: int) -> bool:
    """Whether every one of ``rows`` (rows of an index of ``n``) is one of ``asked``: ``np.isin(rows, asked).all()``."""
    if len(rows) > len(asked):
        return False  # both are unique: more rows than were asked cannot all have been
    seen = np.zeros(n, dtype=bool)
    seen[asked] = True
    return bool(seen[rows].all())


def _kept(i: np.ndarray, j: np.ndarray, rows: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The pairs ``(i, j)`` whose ``i`` is one of ``rows``, in their order."""
    wanted = np.zeros(n, dtype=bool)
    wanted[rows] = True
    keep = wanted[i]
    return i[keep], j[keep]


def brute_gradients(
    points: np.ndarray,
    seps: np.ndarray,
    team: np.ndarray | None = None,
    team_sep: np.ndarray | None = None,
    goals: np.ndarray | None = None,
) -> np.ndarray:
    """``grad phi`` for every unit against every other, ``O(N^2)``: the reference for ``NeighbourIndex``."""
    points, seps = np.asarray(points, dtype=float), np.asarray(seps, dtype=float)
    n = len(points)
    ii, jj = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    i, j = ii.ravel(), jj.ravel()
    gx, gy = _pair_terms(points, pair_separation(points, seps, i, j, team, team_sep, goals), i, j, n)
    return np.column_stack([gx, gy])
