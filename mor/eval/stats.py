"""Statistics of an evaluation: per-seed means, their mean ± std, and a 95% bootstrap interval.

The interval resamples episodes (all seeds' episodes pooled; each episode is an independent layout drawn from
its own seed), with ``scipy.stats.bootstrap``'s BCa method; docs/assumptions.md, "Evaluation", says why
episodes and not the five seed means are resampled.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from scipy import stats


def summarize(values_by_seed: Mapping[int, Sequence[float]], resamples: int = 10_000, seed: int = 0) -> dict:
    """{seed: per-episode values} -> {"mean", "std" (over seed means, ddof=0), "ci95": [lo, hi], "seed_means"}."""
    if not values_by_seed or any(len(v) == 0 for v in values_by_seed.values()):
        raise ValueError("summarize: every seed needs at least one episode")
    seed_means = {int(s): float(np.mean(v)) for s, v in values_by_seed.items()}
    pooled = np.concatenate([np.asarray(v, float) for v in values_by_seed.values()])
    if np.ptp(pooled) == 0.0:
        low = high = float(pooled[0])
    else:
        result = stats.bootstrap((pooled,), np.mean, n_resamples=resamples, confidence_level=0.95, method="BCa",
                                 random_state=np.random.default_rng(seed))
        low, high = float(result.confidence_interval.low), float(result.confidence_interval.high)
    means = np.array(list(seed_means.values()))
    return {"mean": float(means.mean()), "std": float(means.std()), "ci95": [low, high],
            "seed_means": {str(k): v for k, v in seed_means.items()}}
