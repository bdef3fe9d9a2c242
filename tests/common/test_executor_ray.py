"""The executor's Ray engine on a real two-node Ray cluster started on this machine: tasks reach
both nodes, the `pipeline` package is shipped to them, and the workloads give the process
engine's bytes. (A whole `dvc repro` on the Ray engine is in tests/test_pipeline_e2e.py.)"""

from __future__ import annotations

import sys

import numpy as np
import pandas as pd
import pytest

pytestmark = pytest.mark.xdist_group("e2e")  # one Ray cluster at a time on this machine

ray = pytest.importorskip("ray", reason="the ray extra is not installed (pip install -e '.[dev]' brings it)")
from ray.cluster_utils import Cluster  # noqa: E402

from pipeline.common.executor import run_tasks, start_ray  # noqa: E402
from pipeline.data.collect import PairsConfig, collect_pairs_shard  # noqa: E402
from pipeline.data.shards import ShardJob, run_shards, shard_path, write_shard  # noqa: E402
from pipeline.evaluation.benchmark import run_benchmark  # noqa: E402
from pipeline.world.maps import list_maps  # noqa: E402
from pipeline.world.protocol import Protocol  # noqa: E402

ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])  # this file's task functions travel by value


def _where(x: int) -> tuple[int, str, bool]:
    """x squared, the node that ran it, and whether it imported the shipped `pipeline`."""
    import pipeline

    return x * x, ray.get_runtime_context().get_node_id(), "runtime_resources" in pipeline.__file__


def _counting_shard(job: ShardJob) -> dict:
    values = np.random.default_rng([job.params["seed"], job.index]).integers(0, 100, size=job.params["size"])
    write_shard(shard_path(job.out_dir, job.index), {"values": values, "summary_items": np.array(values.size)})
    return {"items": int(values.size)}


@pytest.fixture(scope="module")
def two_nodes():
    """A head node and a worker node, one CPU each, on 127.0.0.1; shut down after this module."""
    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1})
    cluster.add_node(num_cpus=1)
    cluster.wait_for_nodes()
    yield cluster
    ray.shutdown()
    cluster.shutdown()


@pytest.fixture
def on_cluster(two_nodes, monkeypatch):
    """This test's driver joins the two-node cluster through RAY_ADDRESS, as a user's would."""
    monkeypatch.setenv("RAY_ADDRESS", two_nodes.address)
    yield two_nodes
    ray.shutdown()


def test_tasks_run_on_both_nodes_with_the_shipped_package(on_cluster, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # a driver outside the checkout: the nodes cannot import it from their working folder
    results = run_tasks(_where, list(range(12)), 2, "t", "task", backend="ray", progress=False)
    assert [value for value, _, _ in results] == [x * x for x in range(12)]
    nodes = {node["NodeID"] for node in ray.nodes() if node["Alive"]}
    assert len(nodes) == 2 and {node for _, node, _ in results} == nodes
    assert all(shipped for _, _, shipped in results)  # imported from the runtime_env copy, not a checkout


def test_shards_are_the_process_engines_bytes(on_cluster, generated_maze_dir, tmp_path):
    pairs = PairsConfig(
        maps=tuple(str(p) for p in list_maps(generated_maze_dir)),
        pairs_per_shard=3,
        planners=("nearest_frontier", "greedy_utility"),
        snapshot_every=2,
        stop_steps=(3, 12),
        seed=5,
    )
    for name, make, params in (
        ("count", _counting_shard, {"seed": 3, "size": 6}),
        ("pairs", collect_pairs_shard, {"config": pairs}),
    ):
        run_shards(make, 3, tmp_path / f"{name}_p", params, workers=2, backend="process", progress=False)
        run_shards(make, 3, tmp_path / f"{name}_r", params, workers=2, backend="ray", progress=False)
        for k in range(3):
            assert (
                shard_path(tmp_path / f"{name}_p", k).read_bytes() == shard_path(tmp_path / f"{name}_r", k).read_bytes()
            )
        assert (tmp_path / f"{name}_p/manifest.json").read_bytes() == (
            tmp_path / f"{name}_r/manifest.json"
        ).read_bytes()


def test_a_benchmark_gives_the_process_engines_trajectories(on_cluster, generated_maze_dir, tmp_path):
    maps, planners = list_maps(generated_maze_dir)[:2], ["nearest_frontier", "greedy_utility"]
    process = run_benchmark(maps, planners, Protocol(), tmp_path / "p", workers=2, progress=False).frame
    on_ray = run_benchmark(maps, planners, Protocol(), tmp_path / "r", workers=2, progress=False, backend="ray").frame
    columns = ["map", "planner", "distance_m", "steps", "complete", "explored_ratio"]
    pd.testing.assert_frame_equal(process[columns], on_ray[columns])
    for planner in planners:
        for path in maps:
            name = f"{planner}/{path.stem}"
            assert (tmp_path / "p" / f"{name}.csv").read_bytes() == (tmp_path / "r" / f"{name}.csv").read_bytes()
            assert (tmp_path / "p" / f"{name}.steps.csv").read_bytes() != b""
    assert not (tmp_path / "r" / ".episodes").exists()  # complete: nothing left to resume


def test_a_killed_benchmark_resumes_on_the_cluster(on_cluster, tmp_path):
    from benchmark_runs import killed_and_resumed

    kept, output, resumed, whole = killed_and_resumed(
        tmp_path, ("--backend", "ray"), {"RAY_ADDRESS": on_cluster.address}
    )
    assert 18 <= kept < 36
    assert f"episodes: {kept} of 36 kept from an interrupted run" in output
    columns = ["map", "planner", "distance_m", "steps", "complete"]
    pd.testing.assert_frame_equal(resumed[columns], whole[columns])


def test_a_ray_start_cluster_is_not_joined_without_ray_address(two_nodes, monkeypatch):
    """With a cluster running here and RAY_ADDRESS unset, the run starts a private Ray of its own
    size instead of joining (and refusing num_cpus on) the one it would otherwise find."""
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    try:
        start_ray(workers=3)
        alive = [node for node in ray.nodes() if node["Alive"]]
        assert len(alive) == 1 and alive[0]["Resources"]["CPU"] == 3
        assert run_tasks(_where, [2], 3, "t", "task", backend="ray", progress=False)[0][0] == 4
    finally:
        ray.shutdown()
