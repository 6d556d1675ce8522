"""The "as published" Python baseline: the paper's Algorithm 1, written the obvious way.

Per threat, ``scipy.stats.multivariate_normal`` and ``norm.cdf`` evaluate the
skew-normal, and the gradient is the paper's forward difference with
``eps = 1e-10`` (three evaluations per threat per step).  The frozen
distributions are built once per plan, as a careful user would.  This is the
yardstick for ``pfp bench engine``, never used for planning.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy.stats import multivariate_normal, norm

from pfp_service.core import Threat

EPS = 1e-10


class _SkewNormal:
    def __init__(self, t: Threat) -> None:
        self.xi = np.array(t.xi)
        self.mvn = multivariate_normal(mean=self.xi, cov=np.array(t.omega))
        self.a = np.array(t.shape())
        self.weight = t.weight

    def __call__(self, x: np.ndarray) -> float:
        return float(2.0 * self.mvn.pdf(x) * norm.cdf(self.a @ (x - self.xi)))


def baseline_path(
    start: Sequence[float],
    goal: Sequence[float],
    threats: Sequence[Threat],
    delta: float,
    step: float,
    iterations: int,
) -> np.ndarray:
    """Run exactly ``iterations`` steps of Algorithm 1 (density intensity); return the path."""
    fields = [_SkewNormal(t) for t in threats]
    x = np.array(start, dtype=float)
    g = np.array(goal, dtype=float)
    d0sq = float(np.sum((g - x) ** 2))
    path = [x.copy()]
    e1, e2 = np.array([EPS, 0.0]), np.array([0.0, EPS])
    for _ in range(iterations):
        grad = 2.0 * delta / d0sq * (x - g)
        for f in fields:
            t0 = f(x)
            grad = grad + f.weight * np.array([(f(x + e1) - t0) / EPS, (f(x + e2) - t0) / EPS])
        n = math.hypot(grad[0], grad[1])
        if n == 0.0:
            break
        x = x - step * grad / n
        path.append(x.copy())
    return np.array(path)
