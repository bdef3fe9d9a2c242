"""An ordered parallel map with a progress bar: what the per-map and per-shard stages share."""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Callable, Sequence, TypeVar

from tqdm import tqdm

from pipeline.common.kept_results import KeptResults

T = TypeVar("T")
R = TypeVar("R")


def map_with_progress(function: Callable[[T], R], tasks: Sequence[T], workers: int, desc: str, unit: str,
                      keep: KeptResults | None = None) -> list[R]:
    """[function(t) for t in tasks], in task order, over up to `workers` processes (1: in this one).

    `function` must be picklable (a module-level function) when `workers` > 1. With `keep`,
    each result is kept on disk as it finishes and results kept by an earlier, interrupted
    run of the same work are read instead of made again.
    """
    results: dict[int, R] = {}
    if keep is not None:
        results = {index: keep.get(index) for index in range(len(tasks)) if keep.has(index)}
        if results:
            print(f"{desc}: {len(results)} of {len(tasks)} kept from an interrupted run ({keep.folder})")
    todo = [index for index in range(len(tasks)) if index not in results]

    def finished(index: int, result: R) -> None:
        results[index] = result
        if keep is not None:
            keep.put(index, result)
        bar.update()

    with tqdm(total=len(tasks), initial=len(results), desc=desc, unit=unit) as bar:
        if workers <= 1 or len(todo) <= 1:
            for index in todo:
                finished(index, function(tasks[index]))
        else:
            with ProcessPoolExecutor(max_workers=min(workers, len(todo))) as pool:
                futures = {pool.submit(function, tasks[index]): index for index in todo}
                for future in as_completed(futures):
                    finished(futures[future], future.result())
    return [results[index] for index in range(len(tasks))]
