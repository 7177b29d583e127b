"""Statistics of an evaluation: per-seed means, their mean ± std, and a 95% bootstrap interval; over training runs,
their mean ± std, a stratified bootstrap interval over runs and episodes, and the probability of improvement.

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


def verdict(low: float, high: float, lower_is_better: bool = False) -> str:
    """What a 95% interval [low, high] of a difference a - b says: ``helps`` (a better: the interval above 0, below 0
    where lower is better), ``hurts`` (the other way) or ``no evidence``."""
    better, worse = (high < 0, low > 0) if lower_is_better else (low > 0, high < 0)
    return "helps" if better else "hurts" if worse else "no evidence"


def paired_difference(a: Sequence[float], b: Sequence[float], resamples: int = 10_000) -> dict:
    """Per-episode values of two methods on the same episodes -> {"mean", "ci95", "verdict"} of a - b, the interval
    a BCa bootstrap over the episodes' differences."""
    if len(a) != len(b):
        raise ValueError(f"paired_difference: {len(a)} episodes against {len(b)}")
    summary = summarize({0: np.asarray(a, float) - np.asarray(b, float)}, resamples)
    return {"mean": summary["mean"], "ci95": summary["ci95"], "verdict": verdict(*summary["ci95"])}


def _run_bootstrap(values_by_seed: Mapping[str, Sequence[float]], resamples: int, rng: np.random.Generator
                   ) -> np.ndarray:
    """(resamples,) means of one run's episodes, each resampled with replacement within its evaluation seed."""
    total = np.zeros(resamples)
    count = 0
    for values in values_by_seed.values():
        array = np.asarray(values, float)
        total += array[rng.integers(0, len(array), (resamples, len(array)))].sum(axis=1)
        count += len(array)
    return total / count


def summarize_runs(runs: Sequence[Mapping[str, Sequence[float]]], resamples: int = 10_000, seed: int = 0
                   ) -> tuple[dict, np.ndarray]:
    """Training runs' per-episode values ({evaluation seed: values} each) -> ({"mean", "std" (over the runs' means,
    ddof=1; 0 for one run), "ci95" (a stratified bootstrap: runs resampled with replacement, and within each
    drawn run its episodes within each evaluation seed), "iqm" (the interquartile mean of the runs' means, Agarwal et
    al. 2021), "run_means"}, the bootstrap distribution (resamples,) for comparisons)."""
    if not runs:
        raise ValueError("summarize_runs: no runs")
    rng = np.random.default_rng(seed)
    run_means = np.array([np.mean(np.concatenate([np.asarray(v, float) for v in run.values()])) for run in runs])
    per_run = np.stack([_run_bootstrap(run, resamples, rng) for run in runs])  # (R, resamples)
    drawn = rng.integers(0, len(runs), (resamples, len(runs)))
    distribution = per_run[drawn, np.arange(resamples)[:, None]].mean(axis=1)
    low, high = np.percentile(distribution, [2.5, 97.5])
    return ({"mean": float(run_means.mean()), "std": float(run_means.std(ddof=1)) if len(runs) > 1 else 0.0,
             "ci95": [float(low), float(high)], "iqm": float(stats.trim_mean(run_means, 0.25)),
             "run_means": [float(m) for m in run_means]}, distribution)


def probability_of_improvement(a: Sequence[Sequence[float]], b: Sequence[Sequence[float]]) -> float:
    """P(an episode of a run of ``a`` scores above one of a run of ``b``), ties counted half, averaged over every
    pair of runs (a's per-run episode values against b's; Agarwal et al. 2021's probability of improvement)."""
    pairs = []
    for x in a:
        for y in b:
            x_sorted, y_array = np.sort(np.asarray(x, float)), np.asarray(y, float)
            below = np.searchsorted(x_sorted, y_array, side="right")  # a-values <= each b-value
            strictly = np.searchsorted(x_sorted, y_array, side="left")  # a-values < each b-value
            above = len(x_sorted) - below
            ties = below - strictly
            pairs.append(float((above + 0.5 * ties).sum()) / (len(x_sorted) * len(y_array)))
    return float(np.mean(pairs))
