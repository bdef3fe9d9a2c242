"""An ordered parallel map with a progress bar: what the per-map and per-shard stages share."""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor
from typing import Callable, Sequence, TypeVar

from tqdm import tqdm

T = TypeVar("T")
R = TypeVar("R")


def map_with_progress(function: Callable[[T], R], tasks: Sequence[T], workers: int, desc: str, unit: str) -> list[R]:
    """[function(t) for t in tasks], in task order, over up to `workers` processes (1: in this one).

    `function` must be picklable (a module-level function) when `workers` > 1.
    """
    results: list[R] = []
    with tqdm(total=len(tasks), desc=desc, unit=unit) as bar:
        if workers <= 1 or len(tasks) <= 1:
            for task in tasks:
                results.append(function(task))
                bar.update()
        else:
            with ProcessPoolExecutor(max_workers=min(workers, len(tasks))) as pool:
                for result in pool.map(function, tasks):
                    results.append(result)
                    bar.update()
    return results
