"""Confidence intervals for success rates (binomial proportions).

A success rate measured on ``n`` independent episodes with ``k`` successes is reported with
the Wilson score interval (Wilson 1927), which stays inside [0, 1] and keeps close to its
nominal coverage near 0 and 1, where the normal-approximation interval collapses (199/200
gives a Wald interval of [0.985, 1.005] but a Wilson interval of [0.972, 0.999]):

    p_hat = k / n,   z = Phi^-1(1 - alpha / 2)
    centre = (p_hat + z^2 / (2 n)) / (1 + z^2 / n)
    half   = z / (1 + z^2 / n) * sqrt(p_hat (1 - p_hat) / n + z^2 / (4 n^2))
    interval = [centre - half, centre + half]

Pooling the episodes of several training seeds into one interval treats the seeds' policies as
fixed: it covers the episode-sampling noise of *these* policies, not the seed-to-seed spread of
training, which is reported separately (per-seed values).
"""

from __future__ import annotations

import math

from scipy.stats import norm

__all__ = ["wilson_interval"]


def wilson_interval(successes: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Wilson score interval ``(low, high)`` for ``successes`` out of ``n`` trials.

    Returns ``(nan, nan)`` for ``n == 0``. Raises ``ValueError`` for negative counts,
    ``successes > n`` or a confidence outside (0, 1).
    """
    if n < 0 or successes < 0 or successes > n:
        raise ValueError(f"need 0 <= successes <= n, got successes={successes}, n={n}")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence}")
    if n == 0:
        return math.nan, math.nan
    z = float(norm.ppf(0.5 + confidence / 2.0))
    p = successes / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2.0 * n)) / denom
    half = z / denom * math.sqrt(p * (1.0 - p) / n + z * z / (4.0 * n * n))
    low = 0.0 if successes == 0 else max(0.0, centre - half)  # exact ends (no round-off)
    high = 1.0 if successes == n else min(1.0, centre + half)
    return low, high
