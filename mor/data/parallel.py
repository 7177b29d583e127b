"""Mapping a function over items in worker processes: in order with a progress bar (``ordered_map``), or as
each finishes, in processes or as Ray tasks (``unordered_map``)."""

from __future__ import annotations

import multiprocessing as mp
from collections.abc import Callable, Iterator, Sequence
from typing import TypeVar

from tqdm import tqdm

T = TypeVar("T")
R = TypeVar("R")


def ordered_map(function: Callable[[T], R], items: Sequence[T], workers: int = 1, desc: str = "",
                progress: bool = True, chunksize: int = 4) -> list[R]:
    """``[function(item) for item in items]``, in ``workers`` spawned processes (in this one when ``workers <= 1``
    or there are fewer than two items per worker); a tqdm bar over the items. ``function`` and the items must
    pickle (a module-level function)."""
    with tqdm(total=len(items), desc=desc, unit="ep", disable=not progress) as bar:
        if workers <= 1 or len(items) < 2 * workers:
            results = []
            for item in items:
                results.append(function(item))
                bar.update(1)
            return results
        with mp.get_context("spawn").Pool(workers) as pool:
            results = []
            for result in pool.imap(function, items, chunksize=chunksize):
                results.append(result)
                bar.update(1)
            return results


def unordered_map(function: Callable[[T], R], items: Sequence[T], workers: int = 1, backend: str = "process"
                  ) -> Iterator[R]:
    """``function(item)`` for every item, yielded as each finishes (any order): in this process when
    ``workers <= 1``, else in ``workers`` spawned processes (``process``) or as Ray tasks of one CPU each on the
    running Ray cluster, or on a local one started here with ``workers`` CPUs (``ray``). ``function`` and the
    items must pickle (a module-level function)."""
    if backend not in ("process", "ray"):
        raise ValueError(f"backend: unknown backend {backend!r}; choose 'process' or 'ray'")
    if backend == "ray":
        yield from _ray_map(function, items, workers)
    elif workers <= 1 or len(items) < 2:
        yield from (function(item) for item in items)
    else:
        with mp.get_context("spawn").Pool(min(workers, len(items))) as pool:
            yield from pool.imap_unordered(function, items)


def _ray_map(function: Callable[[T], R], items: Sequence[T], workers: int) -> Iterator[R]:
    import ray  # noqa: PLC0415 - optional backend

    started_here = not ray.is_initialized()
    if started_here:
        ray.init(num_cpus=max(1, workers), include_dashboard=False, log_to_driver=False, configure_logging=False)
    remote = ray.remote(num_cpus=1)(function)
    pending = [remote.remote(item) for item in items]
    try:
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            yield ray.get(ready[0])
    finally:
        if started_here:
            ray.shutdown()
