"""The ordered parallel map the per-map and per-shard stages share."""

from pipeline.common.parallel import map_with_progress


def _square_minus(x: int) -> int:
    return x * x - 3


def test_map_with_progress_keeps_task_order_in_one_process_and_in_two():
    tasks = [5, 1, 4, 2, 3]
    expected = [22, -2, 13, 1, 6]
    assert map_with_progress(_square_minus, tasks, 1, "t", "task") == expected
    assert map_with_progress(_square_minus, tasks, 2, "t", "task") == expected


def test_map_with_progress_on_no_tasks_returns_an_empty_list():
    assert map_with_progress(_square_minus, [], 2, "t", "task") == []
