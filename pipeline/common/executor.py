"""One executor for every episode and shard workload, on two engines: local processes or Ray.

`run_tasks(function, tasks, ...)` is `[function(t) for t in tasks]`, in task order, with a
progress bar, on

- `process`: up to `workers` forked processes of this machine (1: in this process);
- `ray`: the tasks of a Ray cluster: the one `RAY_ADDRESS` names (`ray start --head` prints
  it), else a private one started on this machine with `workers` CPUs. A `ray start` cluster
  that runs here while `RAY_ADDRESS` is unset is left alone: joining it silently would refuse
  `num_cpus` and spread one user's run over another's machines.

Results come back to this process through the engine (pickled by the process pool, or Ray's
object store), never through files a worker writes, so no node needs a file system shared
with this one for its results. Ray ships this package to every node (`runtime_env`
`py_modules`), so the nodes run the driver's code and need only the dependencies installed.
What a task reads by path (a maze folder, a data set, a model) it reads from the driver's
working folder where the node has it (the same path on a shared file system, or this machine);
`GUIDE_RAY_WORKING_DIR=.` ships the driver's working folder to every node instead (Ray's
`working_dir`, for data sets of up to a few hundred MB).

The engine is a machine setting, never part of any data's identity: the same tasks give the
same results on both. `resolve_backend` reads it from an explicit value, else the
`GUIDE_BACKEND` environment variable, else `process`.

With `keep` (a `KeptResults`), each result is kept on disk by this process as it finishes, and
results kept by an earlier, killed run of the same work are read instead of made again.
"""

from __future__ import annotations

import importlib.util
import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor, as_completed
from functools import partial
from pathlib import Path
from typing import Any, Callable, Iterator, Sequence, TypeVar

from tqdm import tqdm

from pipeline.common.kept_results import KeptResults

T = TypeVar("T")
R = TypeVar("R")

BACKENDS = ("process", "ray")
BACKEND_ENV = "GUIDE_BACKEND"
WORKING_DIR_ENV = "GUIDE_RAY_WORKING_DIR"
# Never shipped with a working folder: caches, histories and the work of running stages.
WORKING_DIR_EXCLUDES = [".git", ".dvc/cache", ".dvc/tmp", "checkpoints", "mlruns", "mlflow.db", "runs", "__pycache__"]
PACKAGE_DIR = Path(__file__).resolve().parents[1]  # the `pipeline` package Ray ships to its nodes

# What a run shares with every task (`run_tasks(shared=...)`), by run: set before the process pool
# forks, so that its workers take it from their copy of this process instead of a pickle per task.
_SHARED: dict[int, Any] = {}


def resolve_backend(backend: str | None = None) -> str:
    """`backend`, else $GUIDE_BACKEND, else "process"; ValueError for an unknown engine or a
    missing Ray, before any work starts."""
    chosen = backend if backend is not None else (os.environ.get(BACKEND_ENV) or "process")
    if chosen not in BACKENDS:
        source = "" if backend is not None else f" (from ${BACKEND_ENV})"
        raise ValueError(f"unknown backend {chosen!r}{source}: use one of {', '.join(BACKENDS)}")
    if chosen == "ray" and importlib.util.find_spec("ray") is None:
        raise ValueError(
            "backend 'ray' needs Ray, which is not installed: pip install -e '.[ray]' (or use backend process)"
        )
    return chosen


def default_workers() -> int:
    """The cores this process may use."""
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1))


def ray_runtime_env() -> dict[str, Any]:
    """What every Ray worker needs: the `pipeline` package, shipped from here, and with
    $GUIDE_RAY_WORKING_DIR the working folder its tasks read inputs from."""
    env: dict[str, Any] = {"py_modules": [str(PACKAGE_DIR)], "excludes": ["__pycache__", "*.pyc"]}
    if os.environ.get(WORKING_DIR_ENV):
        env["working_dir"] = os.environ[WORKING_DIR_ENV]
        env["excludes"] = env["excludes"] + WORKING_DIR_EXCLUDES
    return env


def start_ray(workers: int | None) -> None:
    """Connect this process to Ray once: the cluster $RAY_ADDRESS names, else a private local one."""
    import ray  # optional dependency: resolve_backend checked it is there

    if ray.is_initialized():
        return
    quiet: dict[str, Any] = {"include_dashboard": False, "log_to_driver": False, "runtime_env": ray_runtime_env()}
    if os.environ.get("RAY_ADDRESS"):
        ray.init(address=os.environ["RAY_ADDRESS"], **quiet)
    else:  # "local": a new cluster of this process's own, even when a `ray start` one runs here
        ray.init(address="local", num_cpus=workers or default_workers(), **quiet)


def _apply(folder: str | None, function: Callable[..., R], *args: Any) -> R:
    """function(*args) in the driver's working `folder` where this node has it (so that relative
    paths read what the driver would): what a Ray task runs (Ray takes plain functions only)."""
    if folder is not None and os.path.isdir(folder):
        os.chdir(folder)
    return function(*args)


def _with_shared(function: Callable[[Any, T], R], token: int, task: T) -> R:
    return function(_SHARED[token], task)


def results_as_finished(
    function: Callable[..., R],
    tasks: Sequence[T],
    indices: Sequence[int],
    workers: int,
    backend: str,
    shared: Any = None,
) -> Iterator[tuple[int, R]]:
    """(index, function(tasks[index])) for each of `indices`, in the order they finish
    (function(shared, tasks[index]) when `shared` is given)."""
    if backend == "ray":
        import ray  # optional dependency: resolve_backend checked it is there

        start_ray(workers)
        remote = ray.remote(num_cpus=1)(_apply)
        folder = None if os.environ.get(WORKING_DIR_ENV) else os.getcwd()  # a shipped working folder is the task's own
        # `function` (small) travels inside each task; `shared` (maps, models) once, through the object store
        if shared is None:
            pending = {remote.remote(folder, function, tasks[index]): index for index in indices}
        else:
            shared_ref = ray.put(shared)
            pending = {remote.remote(folder, function, shared_ref, tasks[index]): index for index in indices}
        try:
            while pending:
                done, _ = ray.wait(list(pending), num_returns=1)
                for ref in done:
                    index = pending.pop(ref)
                    yield index, ray.get(ref)  # re-raises a task's error here
        finally:  # stopped early: the cluster drops what this run still had queued
            for ref in pending:
                ray.cancel(ref)
    elif workers <= 1 or len(indices) <= 1:
        call = function if shared is None else partial(function, shared)
        for index in indices:
            yield index, call(tasks[index])
    else:
        token = id(shared)
        _SHARED[token] = shared
        call = function if shared is None else partial(_with_shared, function, token)
        pool = ProcessPoolExecutor(
            max_workers=min(workers, len(indices)), mp_context=multiprocessing.get_context("fork")
        )
        try:
            futures = {pool.submit(call, tasks[index]): index for index in indices}
            for future in as_completed(futures):
                yield futures[future], future.result()  # re-raises a worker's error here
        finally:  # stopped early (an error, Ctrl-C): the queued tasks are dropped, the running ones end
            pool.shutdown(wait=True, cancel_futures=True)
            _SHARED.pop(token, None)


def run_tasks(
    function: Callable[[T], R],
    tasks: Sequence[T],
    workers: int | None,
    desc: str,
    unit: str,
    keep: KeptResults | None = None,
    backend: str | None = None,
    progress: bool = True,
    on_result: Callable[[int, R], None] | None = None,
    collect: bool = True,
    shared: Any = None,
) -> list[R]:
    """[function(t) for t in tasks], in task order, on `backend`'s engine (see the module docstring).

    `function` and the tasks must be picklable (a module-level function) unless `workers` is 1
    on the process engine. `workers` None is every core here (on Ray: of the private cluster;
    a joined cluster runs as many at once as it has CPUs). `on_result(index, result)` runs in this
    process as each result arrives (kept ones included), after it is kept. With `collect` False
    the results are handed to `on_result` only and not held (large shards), and [] is returned.
    With `shared` (what every task reads: maps, built planners), each call is
    function(shared, task), and `shared` travels once per worker process (forked with it) or per
    Ray node (its object store), not once per task.
    """
    engine = resolve_backend(backend)
    workers = default_workers() if workers is None else int(workers)
    results: dict[int, R] = {}
    if keep is not None:
        results = {index: keep.get(index) for index in range(len(tasks)) if keep.has(index)}
        if results:
            print(f"{desc}: {len(results)} of {len(tasks)} kept from an interrupted run ({keep.folder})")
    if on_result is not None:
        for index in sorted(results):
            on_result(index, results[index])
    todo = [index for index in range(len(tasks)) if index not in results]
    with tqdm(total=len(tasks), initial=len(results), desc=desc, unit=unit, disable=not progress) as bar:
        for index, result in results_as_finished(function, tasks, todo, workers, engine, shared):
            if collect:
                results[index] = result
            if keep is not None:
                keep.put(index, result)
            if on_result is not None:
                on_result(index, result)
            bar.update()
    return [results[index] for index in range(len(tasks))] if collect else []
