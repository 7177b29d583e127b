"""One way to map a function over files in worker processes, in order, with a progress bar."""

from __future__ import annotations

import multiprocessing as mp
from collections.abc import Callable, Sequence
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
