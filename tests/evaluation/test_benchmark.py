import pandas as pd
import pytest

from pipeline.evaluation.benchmark import run_benchmark
from pipeline.workflows.benchmark import benchmark_with_summary
from pipeline.world.map_files import MapError
from pipeline.world.maps import list_maps, load_map
from pipeline.world.protocol import Protocol
from pipeline.world.simulator import replay
from pipeline.world.trajectories import METRICS_COLUMNS, read_trajectory_csv


def test_benchmark_writes_protocol_outputs_that_replay(generated_maze_dir, tmp_path):
    maps = list_maps(generated_maze_dir)[:2]
    frame = benchmark_with_summary(
        maps, ["nearest_frontier", "greedy_utility"], Protocol(), tmp_path, workers=2, progress=False
    ).frame
    metrics = pd.read_csv(tmp_path / "metrics.csv")
    assert list(metrics.columns) == METRICS_COLUMNS
    assert len(metrics) == 4 and metrics["complete"].all()
    assert "| nearest_frontier |" in (tmp_path / "summary.md").read_text()
    for row in metrics.itertuples():
        points = read_trajectory_csv(tmp_path / row.planner / f"{row.map}.csv")
        assert tuple(points[0]) == (0.0, 0.0)
        result = replay(load_map(generated_maze_dir / f"{row.map}.png"), points, Protocol())
        assert result.complete and result.distance_m == pytest.approx(row.distance_m, abs=1e-3)
    assert set(frame["planner"]) == {"nearest_frontier", "greedy_utility"}


def metrics_frame_of(distances: dict[str, list[float]]) -> pd.DataFrame:
    """A metrics.csv-like frame: per planner, one completed episode per map m0, m1, ... with these distances."""
    return pd.DataFrame(
        [
            {
                "map": f"m{i}",
                "planner": planner,
                "distance_m": d,
                "steps": 5,
                "complete": True,
                "explored_ratio": 1.0,
                "decision_ms_median": 1.0,
                "decision_ms_p95": 2.0,
                "seed": 0,
            }
            for planner, values in distances.items()
            for i, d in enumerate(values)
        ]
    )


def test_summary_compares_with_the_baseline_map_by_map():
    from pipeline.reporting.benchmark_markdown import summary_markdown

    frame = metrics_frame_of({"greedy_utility": [100, 200, 300], "nf": [110, 220, 330]})
    text = summary_markdown(frame, Protocol())
    assert "vs greedy_utility (paired, 95 %)" in text
    assert (
        "| nf | 3 | 220.0 +- 89.8 | +10.0 % +- 12.4 |" in text
    )  # differences 10, 20, 30 m over a 200 m mean; t(2 dof)
    assert "| greedy_utility | 3 | 200.0 +- 81.6 | — |" in text
    assert "vs " not in summary_markdown(frame, Protocol(), baseline=None)
    assert "vs " not in summary_markdown(frame[frame.planner == "nf"], Protocol())  # the baseline did not run
    single = summary_markdown(metrics_frame_of({"greedy_utility": [100], "nf": [110]}), Protocol())
    assert "| nf | 1 | 110.0 | +10.0 % |" in single and "+- 0.0" not in single  # one episode has no spread


def test_gap_to_optimal_is_the_mean_over_the_references_mean_minus_one():
    from pipeline.evaluation.statistics import summarise
    from pipeline.reporting.benchmark_markdown import summary_markdown

    frame = metrics_frame_of({"optimal": [80, 160, 240], "nf": [110, 220, 330]})
    summary = summarise(frame)
    assert summary.loc["nf", "gap_to_optimal"] == pytest.approx(220 / 160 - 1.0)
    assert summary.loc["optimal", "gap_to_optimal"] == pytest.approx(0.0)
    text = summary_markdown(frame, Protocol(), baseline=None)
    assert "| nf | 3 | 220.0 +- 89.8 | +37.5 % |" in text and "| optimal | 3 | 160.0 +- 65.3 | +0.0 % |" in text
    assert "gap to optimal" not in summary_markdown(frame[frame.planner == "nf"], Protocol(), baseline=None)


def test_benchmark_rejects_unknown_planner_and_bad_maps(generated_maze_dir, tmp_path):
    with pytest.raises(KeyError, match="unknown planner"):
        run_benchmark(list_maps(generated_maze_dir), ["no_such_planner"], Protocol(), tmp_path)
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"not an image")
    with pytest.raises(MapError, match="bad.png"):
        run_benchmark([bad], ["nearest_frontier"], Protocol(), tmp_path / "out")


def test_failures_are_reported_not_dropped(small_maze_path, tmp_path):
    maps = [small_maze_path]
    frame = benchmark_with_summary(
        maps, ["nearest_frontier"], Protocol(max_steps=2), tmp_path, workers=1, progress=False
    ).frame
    assert len(frame) == 1 and not frame["complete"].any()
    assert "step limit" in (tmp_path / "summary.md").read_text()


def test_an_episode_runs_its_spec_on_the_inputs_and_is_labelled_by_it(small_maze_path):
    from pipeline.evaluation.benchmark import BenchmarkInputs, EpisodeTask, MapSet, run_task
    from pipeline.planners.specs import PlannerSpec, build_planner, parse_planner_spec, resolve_planner_specs

    variant = parse_planner_spec("nf_u1=nearest_frontier:min_utility=1")
    inputs = BenchmarkInputs(MapSet((str(small_maze_path),), Protocol(max_steps=2)), {variant: build_planner(variant)})
    assert run_task(inputs, EpisodeTask(str(small_maze_path), variant, 0)).planner == "nf_u1"
    assert {variant: 1}[PlannerSpec("nf_u1", "nearest_frontier", {"min_utility": 1})] == 1  # a spec keys its planner
    specs = resolve_planner_specs(["greedy_utility", PlannerSpec("nf_u1", "nearest_frontier", {"min_utility": 1})])
    assert [(s.label, s.name, s.options) for s in specs] == [
        ("greedy_utility", "greedy_utility", {}),
        ("nf_u1", "nearest_frontier", {"min_utility": 1}),
    ]


def test_benchmark_records_what_ran_and_applies_one_start(generated_maze_dir, tmp_path):
    import json

    maps = list_maps(generated_maze_dir)[:1]
    own = load_map(maps[0])
    col, row = own.start_cell
    start = next(
        (c, r) for c, r in ((col + 10, row), (col, row + 10), (col - 10, row), (col, row - 10)) if own.free[r, c]
    )  # a free cell 4 m from the marked start
    run_benchmark(
        maps, ["nf=nearest_frontier:min_utility=3"], Protocol(), tmp_path, workers=1, progress=False, start=start
    )
    record = json.loads((tmp_path / "run.json").read_text())
    assert record["start"] == list(start) and record["seed"] == 0
    assert record["protocol"] == Protocol().to_dict() and record["maps"] == [str(maps[0])]
    assert record["planners"]["nf"]["name"] == "nearest_frontier"
    assert record["planners"]["nf"]["options"] == {"min_utility": 3}
    assert record["planners"]["nf"]["description"]
    points = read_trajectory_csv(tmp_path / "nf" / f"{maps[0].stem}.csv")
    moved = load_map(maps[0], start=start)
    assert replay(moved, points, Protocol()).complete  # the trajectory is relative to the given start
    assert not replay(own, points, Protocol()).complete  # and breaks the rules from the marked one


def test_a_map_with_too_few_free_cells_is_refused(tmp_path):
    import numpy as np

    grid = np.zeros((40, 40), dtype=np.uint8)
    grid[10:20, 10:20] = 1  # 100 free cells: complete under done_unknown_cells=250 before any move
    np.save(tmp_path / "tiny.npy", grid)
    with pytest.raises(MapError, match="only 100 free cells, not more than done_unknown_cells=250") as info:
        run_benchmark([tmp_path / "tiny.npy"], ["nearest_frontier"], Protocol(), tmp_path / "out", start=(12, 12))
    assert str(info.value).startswith(f"{tmp_path / 'tiny.npy'}: ")  # the file, not just its stem
    frame = run_benchmark(
        [tmp_path / "tiny.npy"],
        ["nearest_frontier"],
        Protocol(done_unknown_cells=10),
        tmp_path / "out",
        workers=1,
        progress=False,
        start=(12, 12),
    ).frame
    assert frame["complete"].all()


def test_a_protocol_mismatch_is_said_once_before_the_episodes(generated_maze_dir, tmp_path):
    """Not once per episode and worker: the planners are checked in the calling process, the workers stay quiet."""
    import warnings

    from pipeline.models import defaults
    from pipeline.world.protocol import ProtocolMismatchWarning

    shipped = defaults.SHIPPED_INPAINTER
    maps = list_maps(generated_maze_dir)[:2]
    spec = f"tsp=guide_tsp:inpainter_file={shipped}"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        run_benchmark(maps, [spec], Protocol(node_resolution=2.0, max_steps=2), tmp_path, workers=1, progress=False)
    said = [w for w in caught if issubclass(w.category, ProtocolMismatchWarning)]
    assert len(said) == 1 and "node_resolution 4 -> 2" in str(said[0].message)


def test_a_ros_map_is_recorded_and_summarised_at_its_own_cell_size(tmp_path):
    """The protocol's cell size (0.4 m) does not apply to a ROS map: its own (0.2 m) is what ran."""
    import json
    from dataclasses import replace

    from pipeline.world.protocol import PAPER_REAL_ROBOT
    from tests.conftest import write_ros_map
    from tests.world.test_simulator import office_grid

    maps = tmp_path / "ros"
    maps.mkdir()
    free, start = office_grid()
    write_ros_map(maps, free, 0.2, start)
    protocol = replace(PAPER_REAL_ROBOT, cell_size=0.4, done_unknown_cells=50)
    benchmark_with_summary(list_maps(maps), ["nearest_frontier"], protocol, tmp_path / "b", workers=1, progress=False)
    record = json.loads((tmp_path / "b" / "run.json").read_text())
    assert record["protocol"]["cell_size"] == 0.2 and record["protocol"]["node_resolution"] == 1.0
    summary = (tmp_path / "b" / "summary.md").read_text()
    assert "Protocol: cell_size=0.2, node_resolution=1.0" in summary


def test_a_reused_output_folder_with_other_planners_results_is_warned_about(generated_maze_dir, tmp_path):
    maps = list_maps(generated_maze_dir)[:1]
    run_benchmark(maps, ["nearest_frontier"], Protocol(), tmp_path, workers=1, progress=False)
    with pytest.warns(
        UserWarning, match=r"holds trajectories of planners this run does not write \(nearest_frontier\)"
    ):
        run_benchmark(maps, ["greedy_utility"], Protocol(), tmp_path, workers=1, progress=False)
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        run_benchmark(
            maps, ["greedy_utility", "nearest_frontier"], Protocol(), tmp_path, workers=1, progress=False
        )  # all rewritten: quiet


def test_an_interrupted_benchmark_keeps_the_finished_episodes(generated_maze_dir, tmp_path, monkeypatch):
    """Ctrl-C after one episode: its trajectory, metrics.csv and summary.md stay; the CLI exits 130."""
    from typer.testing import CliRunner

    import pipeline.evaluation.benchmark as benchmark
    from pipeline.cli import app

    finished = benchmark.run_task

    def interrupt_after_the_first(inputs, task):
        if interrupt_after_the_first.calls:
            raise KeyboardInterrupt
        interrupt_after_the_first.calls += 1
        return finished(inputs, task)

    interrupt_after_the_first.calls = 0
    monkeypatch.setattr(benchmark, "run_task", interrupt_after_the_first)
    result = CliRunner().invoke(
        app,
        [
            "benchmark",
            "--maps",
            str(generated_maze_dir),
            "--planner",
            "nearest_frontier",
            "--out",
            str(tmp_path / "b"),
            "--workers",
            "1",
            "--no-mlflow",
        ],
    )
    assert result.exit_code == 130
    assert f"interrupted after 1 of 3 episodes; {tmp_path / 'b'}/metrics.csv and summary.md hold them" in result.output
    metrics = pd.read_csv(tmp_path / "b" / "metrics.csv")
    assert len(metrics) == 1 and bool(metrics["complete"].iloc[0])
    assert "nearest_frontier" in (tmp_path / "b" / "summary.md").read_text()


@pytest.mark.slow
def test_a_killed_benchmark_resumes_with_its_finished_episodes(tmp_path):
    from benchmark_runs import killed_and_resumed

    kept, output, resumed, whole = killed_and_resumed(tmp_path)
    assert 18 <= kept < 36
    assert f"episodes: {kept} of 36 kept from an interrupted run" in output
    columns = ["map", "planner", "distance_m", "steps", "complete"]
    pd.testing.assert_frame_equal(resumed[columns], whole[columns])
    assert not (tmp_path / "killed/.episodes").exists()


def test_episodes_kept_outside_the_output_folder_carry_over_to_a_new_one(generated_maze_dir, tmp_path, monkeypatch):
    """As the benchmark stage runs it: each attempt writes a fresh (temporary) output folder, and
    the finished episodes of a killed attempt, kept in `keep_dir`, are taken up by the next."""
    import pipeline.evaluation.benchmark as benchmark

    finished, calls = benchmark.run_task, []

    def interrupt_after_the_first(inputs, task):
        if calls:
            raise KeyboardInterrupt
        calls.append(task)
        return finished(inputs, task)

    monkeypatch.setattr(benchmark, "run_task", interrupt_after_the_first)
    maps, keep = list_maps(generated_maze_dir), tmp_path / "checkpoints" / "benchmark"
    with pytest.raises(benchmark.BenchmarkInterrupted):
        run_benchmark(
            maps, ["nearest_frontier"], Protocol(), tmp_path / "first", workers=1, progress=False, keep_dir=keep
        )
    assert len(list(keep.glob("item_*.pkl"))) == 1 and not (tmp_path / "first" / ".episodes").exists()

    ran = []
    monkeypatch.setattr(benchmark, "run_task", lambda inputs, task: ran.append(task) or finished(inputs, task))
    run = run_benchmark(
        maps, ["nearest_frontier"], Protocol(), tmp_path / "second", workers=1, progress=False, keep_dir=keep
    )
    assert len(ran) == 2 and len(run.frame) == 3  # the kept episode was not run again
    assert not keep.exists()  # a complete run leaves nothing kept


def test_a_planner_that_raises_fails_its_episode_and_the_run_goes_on(generated_maze_dir, tmp_path, monkeypatch):
    """A planner raising on one map: that episode is recorded (map, planner, error, its trajectory so
    far), the others run, the tracebacks go to errors.txt, and the CLI exits 1 with the list."""
    from typer.testing import CliRunner

    from pipeline.cli import app
    from pipeline.planners.baselines.frontier import NearestFrontierPlanner

    maps = list_maps(generated_maze_dir)
    broken = maps[1].stem
    reset, plan = NearestFrontierPlanner.reset, NearestFrontierPlanner.plan

    def remember_the_map(self, frame, protocol, seed):
        self.test_map = frame.name
        reset(self, frame, protocol, seed)

    def raise_on_one_map(self, observation):
        if observation.step == 2 and self.test_map == broken:
            raise RuntimeError("Padding size should be less than the corresponding input dimension")
        return plan(self, observation)

    monkeypatch.setattr(NearestFrontierPlanner, "reset", remember_the_map)
    monkeypatch.setattr(NearestFrontierPlanner, "plan", raise_on_one_map)
    run = run_benchmark(maps, ["nearest_frontier"], Protocol(), tmp_path / "a", workers=1, progress=False)
    assert len(pd.read_csv(tmp_path / "a" / "metrics.csv")) == len(maps)
    failed = run.frame[~run.frame["complete"].astype(bool)]
    assert list(failed["map"]) == [broken]
    assert (
        failed["failure"].iloc[0]
        == "planner error: RuntimeError: Padding size should be less than the corresponding input dimension"
    )
    assert len(read_trajectory_csv(tmp_path / "a" / "nearest_frontier" / f"{broken}.csv")) >= 2  # the trajectory so far
    assert run.errors == [(broken, "nearest_frontier", failed["failure"].iloc[0])]
    assert "Traceback" in (tmp_path / "a" / "errors.txt").read_text()
    result = CliRunner().invoke(
        app,
        [
            "benchmark",
            "--maps",
            str(generated_maze_dir),
            "--planner",
            "nearest_frontier",
            "--out",
            str(tmp_path / "b"),
            "--workers",
            "1",
            "--no-mlflow",
        ],
    )
    assert result.exit_code == 1
    assert f"1 episode failed with a planner error (tracebacks in {tmp_path / 'b' / 'errors.txt'})" in result.output
    assert f"nearest_frontier on {broken}: planner error: RuntimeError" in result.output


def test_a_benchmark_reads_and_hashes_its_map_folder_once_and_parses_each_spec_once(
    generated_maze_dir, tmp_path, monkeypatch
):
    """`guide benchmark`'s workflow with MLflow: the maps are loaded once each, the folder hashed once
    (run identity and MLflow's dataset input share the digest), each spec string parsed once."""
    import pipeline.common.mlflow_store as mlflow_store
    import pipeline.evaluation.benchmark as benchmark
    import pipeline.planners.specs as specs
    from pipeline.workflows.benchmark import benchmark_folder

    calls = {"load": [], "digest": 0, "parse": []}
    load, digest, parse = benchmark.load_map, benchmark.files_digest, specs.parse_planner_spec

    def counted_load(path, **kwargs):
        calls["load"].append(str(path))
        return load(path, **kwargs)

    def counted_digest(paths):
        calls["digest"] += 1
        return digest(paths)

    def counted_parse(text, *args):
        calls["parse"].append(text)
        return parse(text, *args)

    monkeypatch.setattr(benchmark, "load_map", counted_load)
    monkeypatch.setattr(benchmark, "files_digest", counted_digest)
    monkeypatch.setattr(mlflow_store, "files_digest", counted_digest)
    monkeypatch.setattr(specs, "parse_planner_spec", counted_parse)
    planners = ["nearest_frontier", "g5=greedy_utility:min_utility=5"]
    benchmark_folder(
        generated_maze_dir,
        planners,
        Protocol(max_steps=3),
        tmp_path / "out",
        workers=1,
        tracking_uri=f"sqlite:///{tmp_path / 'mlflow.db'}",
    )
    assert sorted(calls["load"]) == sorted(map(str, list_maps(generated_maze_dir)))
    assert calls["digest"] == 1
    assert calls["parse"] == planners
