"""The one executor every episode and shard workload runs on (the process engine here; Ray in
test_executor_ray.py)."""

import os

import pytest

from pipeline.common.executor import BACKEND_ENV, resolve_backend, run_tasks
from pipeline.common.kept_results import KeptResults


def _square_minus(x: int) -> int:
    return x * x - 3


def _scaled(shared: dict, x: int) -> tuple[int, int]:
    return shared["factor"] * x, os.getpid()


def test_run_tasks_keeps_task_order_in_one_process_and_in_two():
    tasks = [5, 1, 4, 2, 3]
    expected = [22, -2, 13, 1, 6]
    assert run_tasks(_square_minus, tasks, 1, "t", "task") == expected
    assert run_tasks(_square_minus, tasks, 2, "t", "task") == expected


def test_run_tasks_on_no_tasks_returns_an_empty_list():
    assert run_tasks(_square_minus, [], 2, "t", "task") == []


def test_shared_inputs_reach_every_task_in_forked_workers():
    shared = {"factor": 7}
    results = run_tasks(_scaled, [1, 2, 3, 4], 2, "t", "task", shared=shared)
    assert [value for value, _ in results] == [7, 14, 21, 28]
    assert os.getpid() not in {pid for _, pid in results}  # ran in the pool's processes
    assert [value for value, _ in run_tasks(_scaled, [5], 1, "t", "task", shared=shared)] == [35]


def test_results_are_handed_over_as_they_arrive_and_kept_for_a_rerun(tmp_path):
    seen: dict[int, int] = {}
    keep = KeptResults(tmp_path / "kept", {"work": "squares"})
    assert (
        run_tasks(_square_minus, [1, 2, 3], 2, "t", "task", keep=keep, on_result=seen.__setitem__, collect=False) == []
    )
    assert seen == {0: -2, 1: 1, 2: 6} and keep.count() == 3
    calls = []
    again = run_tasks(
        lambda x: calls.append(x) or _square_minus(x),
        [1, 2, 3, 4],
        1,
        "t",
        "task",
        keep=KeptResults(tmp_path / "kept", {"work": "squares"}),
    )
    assert again == [-2, 1, 6, 13] and calls == [4]  # only the task the first run did not finish


def test_the_engine_comes_from_the_argument_then_the_environment(monkeypatch):
    monkeypatch.delenv(BACKEND_ENV, raising=False)
    assert resolve_backend(None) == "process"
    monkeypatch.setenv(BACKEND_ENV, "process")
    assert resolve_backend(None) == "process"
    monkeypatch.setenv(BACKEND_ENV, "dask")
    with pytest.raises(ValueError, match=r"unknown backend 'dask' \(from \$GUIDE_BACKEND\): use one of process, ray"):
        resolve_backend(None)
    with pytest.raises(ValueError, match="unknown backend 'spark': use one of process, ray"):
        run_tasks(_square_minus, [1], 1, "t", "task", backend="spark")
