import json
import warnings

import cv2
import numpy as np
import pandas as pd
import pytest
from import_graph import ROOT
from typer.testing import CliRunner

from pipeline.cli import app
from pipeline.world.mazes import write_maze_png
from tests.conftest import maze_from_blocks

runner = CliRunner()


def test_planners_lists_every_name():
    result = runner.invoke(app, ["planners"])
    assert result.exit_code == 0
    for name in ("nearest_frontier", "greedy_utility", "nbvp"):
        assert name in result.output


def test_every_command_has_help():
    for command in (
        ["--help"],
        ["explore", "--help"],
        ["benchmark", "--help"],
        ["replay", "--help"],
        ["mazes", "--help"],
        ["resample-map", "--help"],
        ["eval-predictor", "--help"],
        ["planners", "--help"],
    ):
        result = runner.invoke(app, command)
        assert result.exit_code == 0 and "Usage" in result.output


def test_explore_writes_trajectory_metrics_png_and_gif(small_maze_path, tmp_path):
    out = tmp_path / "demo"
    result = runner.invoke(
        app, ["explore", "--map", str(small_maze_path), "--planner", "nearest_frontier", "--out", str(out), "--gif"]
    )
    assert result.exit_code == 0, result.output
    for name in ("small.csv", "metrics.csv", "small.png", "small.gif"):
        assert (out / name).is_file(), name
    metrics = pd.read_csv(out / "metrics.csv")
    assert bool(metrics.loc[0, "complete"])
    replayed = runner.invoke(app, ["replay", "--map", str(small_maze_path), "--trajectory", str(out / "small.csv")])
    assert replayed.exit_code == 0
    report = json.loads(replayed.output)
    assert report["complete"] and report["distance_m"] == pytest.approx(metrics.loc[0, "distance_m"], abs=1e-3)
    assert report["steps"] == metrics.loc[0, "steps"] == report["complete_after_waypoint"] - 1


@pytest.mark.parametrize(
    "make_bad, reason",
    [
        (lambda d: d / "missing.png", "file not found"),
        (lambda d: (d / "junk.png").write_bytes(b"\x00garbage") and d / "junk.png", "not a readable image"),
        (lambda d: np.save(d / "cube.npy", np.ones((3, 3, 3), dtype=np.uint8)) or d / "cube.npy", "2-D"),
    ],
)
def test_bad_maps_exit_2_with_one_line(tmp_path, make_bad, reason):
    path = make_bad(tmp_path)
    result = runner.invoke(app, ["explore", "--map", str(path), "--out", str(tmp_path / "o"), "--start", "1", "1"])
    assert result.exit_code == 2
    lines = [line for line in result.output.strip().splitlines() if line]
    assert len(lines) == 1 and str(path.name) in lines[0] and reason in lines[0]
    assert "Traceback" not in result.output


def test_unknown_planner_exits_2(small_maze_path, tmp_path):
    result = runner.invoke(app, ["explore", "--map", str(small_maze_path), "--planner", "nope", "--out", str(tmp_path)])
    assert result.exit_code == 2 and "unknown planner" in result.output


def test_benchmark_command_logs_one_mlflow_run_per_planner(generated_maze_dir, tmp_path, mlflow_uri):
    out = tmp_path / "bench"
    result = runner.invoke(
        app,
        [
            "benchmark",
            "--maps",
            str(generated_maze_dir),
            "--planner",
            "nearest_frontier",
            "--planner",
            "greedy=greedy_utility:min_utility=3",
            "--out",
            str(out),
            "--workers",
            "2",
            "--tracking-uri",
            mlflow_uri,
            "--experiment",
            "cli-test",
        ],
    )
    assert result.exit_code == 0, result.output
    assert (out / "metrics.csv").is_file() and (out / "summary.md").is_file() and (out / "run.json").is_file()
    import mlflow

    mlflow.set_tracking_uri(mlflow_uri)
    runs = mlflow.search_runs(experiment_names=["cli-test"]).set_index("tags.mlflow.runName")
    assert sorted(runs.index) == ["greedy", "nearest_frontier"]
    assert (runs["metrics.completion_rate"] == 1.0).all()
    assert runs.loc["greedy", "params.planner_name"] == "greedy_utility"
    assert json.loads(runs.loc["greedy", "params.planner_options"]) == {"min_utility": 3}
    assert runs.loc["nearest_frontier", "params.planner_description"].startswith("Yamauchi")


def test_mazes_draws_loadable_benchmark_mazes_and_refuses_a_used_folder(tmp_path):
    from pipeline.world.maps import load_map

    out = tmp_path / "set"
    result = runner.invoke(app, ["mazes", "--out", str(out), "--count", "2", "--seed", "5", "--side", "30"])
    assert result.exit_code == 0, result.output
    paths = sorted(out.glob("maze_*.png"))
    assert [p.name for p in paths] == ["maze_0000.png", "maze_0001.png"]
    assert paths[0].stat().st_mode & 0o777 == 0o644  # readable by others, unlike mkstemp's 0600
    first = load_map(paths[0])
    assert first.free.shape == (75, 75) and first.free.any()  # 30 m at 0.4 m cells
    again = runner.invoke(
        app, ["mazes", "--out", str(tmp_path / "again"), "--count", "1", "--seed", "5", "--side", "30"]
    )
    assert again.exit_code == 0
    assert (tmp_path / "again" / "maze_0000.png").read_bytes() == paths[0].read_bytes()  # the seed fixes the maze
    used = runner.invoke(app, ["mazes", "--out", str(out), "--count", "1"])
    assert used.exit_code == 2 and "already holds 2 maze PNGs" in used.output
    odd = runner.invoke(app, ["mazes", "--out", str(tmp_path / "odd"), "--count", "1", "--side", "7"])
    assert odd.exit_code == 2 and "--side 7 holds no whole number" in odd.output
    huge = _one_error_line(
        runner.invoke(app, ["mazes", "--out", str(tmp_path / "huge"), "--count", "1", "--side", "1e9"])
    )
    assert "more than the map loader reads; the largest side at 0.4 m cells is 1635 m" in huge  # not a MemoryError


def test_mazes_draws_office_floors_on_request(tmp_path):
    from pipeline.world.maps import load_map

    out = tmp_path / "offices"
    result = runner.invoke(
        app, ["mazes", "--out", str(out), "--count", "2", "--seed", "5", "--side", "40", "--kind", "office"]
    )
    assert result.exit_code == 0, result.output
    paths = sorted(out.glob("office_*.png"))
    assert [p.name for p in paths] == ["office_0000.png", "office_0001.png"]
    floor = load_map(paths[0])
    assert floor.free.shape == (100, 100) and floor.free.mean() > 0.7  # open floors, not mazes
    assert "already holds office PNGs" in _one_error_line(
        runner.invoke(app, ["mazes", "--out", str(out), "--count", "1", "--kind", "office"])
    )
    assert "--kind must be maze, office, building or cave" in _one_error_line(
        runner.invoke(app, ["mazes", "--out", str(tmp_path / "k"), "--count", "1", "--kind", "hut"])
    )
    assert "side_m >= 20 m" in _one_error_line(
        runner.invoke(app, ["mazes", "--out", str(tmp_path / "s"), "--count", "1", "--kind", "office", "--side", "10"])
    )
    huge = _one_error_line(
        runner.invoke(app, ["mazes", "--out", str(tmp_path / "h"), "--count", "1", "--kind", "office", "--side", "1e9"])
    )
    assert "the largest side at 0.4 m cells is" in huge


def test_mazes_draws_caves_on_request(tmp_path):
    from pipeline.world.maps import load_map

    out = tmp_path / "caves"
    result = runner.invoke(
        app, ["mazes", "--out", str(out), "--count", "2", "--seed", "5", "--side", "40", "--kind", "cave"]
    )
    assert result.exit_code == 0, result.output
    assert "wrote 2 caves of 40 m" in result.output
    paths = sorted(out.glob("cave_*.png"))
    assert [p.name for p in paths] == ["cave_0000.png", "cave_0001.png"]
    assert load_map(paths[0]).free.shape == (100, 100)
    assert "already holds cave PNGs" in _one_error_line(
        runner.invoke(app, ["mazes", "--out", str(out), "--count", "1", "--kind", "cave"])
    )
    assert "caves need cell_size > 0 and side_m >= 20 m" in _one_error_line(
        runner.invoke(app, ["mazes", "--out", str(tmp_path / "s"), "--count", "1", "--kind", "cave", "--side", "10"])
    )
    assert "the 4 m block 4 m is under 4 cells" in _one_error_line(
        runner.invoke(
            app, ["mazes", "--out", str(tmp_path / "c"), "--count", "1", "--kind", "cave", "--cell-size", "1.5"]
        )
    )


def _one_error_line(result) -> str:
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    lines = [line for line in result.output.strip().splitlines() if line]
    assert len(lines) == 1 and lines[0].startswith("error: "), result.output
    return lines[0]


def test_an_out_path_that_is_a_file_fails_before_any_work(small_maze_path, generated_maze_dir, tmp_path):
    taken = tmp_path / "taken"
    taken.write_text("x")
    for command in (
        ["explore", "--map", str(small_maze_path), "--out", str(taken)],
        ["benchmark", "--maps", str(generated_maze_dir), "--planner", "nearest_frontier", "--out", str(taken)],
        ["eval-predictor", "--maps", str(generated_maze_dir), "--out", str(taken)],
        ["mazes", "--out", str(taken), "--count", "1"],
    ):
        assert "exists and is not a folder" in _one_error_line(runner.invoke(app, command))


def test_checkpoint_options_are_checked(small_maze_path, generated_maze_dir, tmp_path):
    fake = tmp_path / "fake.pt"
    fake.write_text("not a checkpoint")
    explore = ["explore", "--map", str(small_maze_path), "--out", str(tmp_path / "o")]
    line = _one_error_line(runner.invoke(app, explore + ["--planner", "guide", "--checkpoint", str(fake)]))
    assert "not a planner checkpoint (not a file written by torch.save)" in line
    line = _one_error_line(runner.invoke(app, explore + ["--planner", f"g=guide_tsp:inpainter_file={fake}"]))
    assert "not an inpainter export" in line
    line = _one_error_line(runner.invoke(app, explore + ["--planner", "guide_tsp", "--checkpoint", str(fake)]))
    assert "no planner given uses one" in line  # --checkpoint is a policy; guide_tsp has none
    line = _one_error_line(
        runner.invoke(app, explore + ["--planner", "guide", "--checkpoint", str(tmp_path / "nope.pt")])
    )
    assert "file not found" in line
    line = _one_error_line(runner.invoke(app, explore + ["--planner", "guide", "--checkpoint", str(tmp_path)]))
    assert "a folder, not a file" in line
    assets = ROOT / "pipeline" / "assets"
    line = _one_error_line(
        runner.invoke(app, explore + ["--planner", "guide", "--checkpoint", str(assets / "inpainter.pt")])
    )
    assert "an inpainter export, not a planner policy" in line  # named for what it is, not by its config keys
    line = _one_error_line(
        runner.invoke(app, explore + ["--planner", f"t=guide_tsp:inpainter_file={assets / 'planner_guide.pt'}"])
    )
    assert "a planner policy export, not an inpainter export" in line
    line = _one_error_line(
        runner.invoke(
            app,
            [
                "eval-predictor",
                "--maps",
                str(generated_maze_dir),
                "--out",
                str(tmp_path / "p"),
                "--checkpoint",
                str(fake),
            ],
        )
    )
    assert "not an inpainter export" in line


def test_eval_predictor_threshold_outside_0_1_is_refused(generated_maze_dir, tmp_path):
    result = runner.invoke(
        app, ["eval-predictor", "--maps", str(generated_maze_dir), "--out", str(tmp_path / "p"), "--threshold", "1.5"]
    )
    assert result.exit_code == 2 and "--threshold" in result.output and "Traceback" not in result.output
    assert not (tmp_path / "p").exists()


def test_benchmark_baseline_must_name_a_planner(generated_maze_dir, tmp_path):
    result = runner.invoke(
        app,
        [
            "benchmark",
            "--maps",
            str(generated_maze_dir),
            "--planner",
            "nearest_frontier",
            "--baseline",
            "nope",
            "--out",
            str(tmp_path / "b"),
            "--no-mlflow",
        ],
    )
    assert "--baseline 'nope' is not among the planners' labels: nearest_frontier" in _one_error_line(result)


def test_replay_exits_1_when_the_trajectory_does_not_complete(small_maze_path, tmp_path):
    partial = tmp_path / "partial.csv"
    partial.write_text("x,y\n0,0\n")
    result = runner.invoke(app, ["replay", "--map", str(small_maze_path), "--trajectory", str(partial)])
    assert result.exit_code == 1 and json.loads(result.output)["complete"] is False


def test_help_keeps_literal_brackets():
    assert "[default: all cores]" in runner.invoke(app, ["benchmark", "--help"]).output


def test_explore_records_the_run_and_defaults_to_a_folder_per_planner(small_maze_path, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for planner in ("nearest_frontier", "nf3=nearest_frontier:min_utility=3"):
        result = runner.invoke(app, ["explore", "--map", str(small_maze_path), "--planner", planner, "--no-progress"])
        assert result.exit_code == 0, result.output
    for label, options in (("nearest_frontier", {}), ("nf3", {"min_utility": 3})):
        out = tmp_path / "runs" / "explore" / label  # two planners, two folders: nothing overwritten
        record = json.loads((out / "run.json").read_text())
        assert record["planner"]["label"] == label and record["planner"]["options"] == options
        assert record["map"] == str(small_maze_path) and record["protocol"]["sensor_range"] == 20.0
        assert (out / "small.csv").is_file()


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--sensor-range", "nan"], "error: --sensor-range: must be a finite number > 0 (metres), got nan"),
        (
            ["--node-resolution", "inf"],
            "error: --node-resolution: must be a finite number > 0 (lattice spacing in metres), got inf",
        ),
        (["--done-unknown-cells", "-3"], "error: --done-unknown-cells: must be a whole number >= 0 (cells), got -3"),
        (["--node-resolution", "0.1"], "error: protocol: node_resolution (0.1 m) must be at least one cell (0.4 m)"),
        (["--sensor-range", "1000"], "more than twice the map's diagonal"),
        (["--planner", "x=greedy_utility:min_utility=nan"], "must be a finite number"),
        (
            ["--planner", "g=guide:min_utility=-1"],
            "error: planner 'g': min_utility: must be a whole number >= 1, got -1",
        ),
        (["--planner", "g=guide:sampler=euler"], "error: planner 'g': sampler: must be one of 'ddpm', 'ddim', or null"),
    ],
)
def test_explore_refuses_values_that_make_no_sense(small_maze_path, tmp_path, extra, message):
    args = ["explore", "--map", str(small_maze_path), "--out", str(tmp_path / "o"), *extra]
    assert message in _one_error_line(runner.invoke(app, args))


def test_an_out_folder_that_cannot_be_made_fails_before_any_work(small_maze_path, generated_maze_dir, tmp_path):
    blocked = tmp_path / "a_file"
    blocked.write_text("x")
    for command in (
        ["explore", "--map", str(small_maze_path)],
        ["benchmark", "--maps", str(generated_maze_dir), "--planner", "nearest_frontier", "--no-mlflow"],
        ["mazes", "--count", "1"],
    ):
        line = _one_error_line(runner.invoke(app, [*command, "--out", str(blocked / "sub")]))
        assert "cannot create or write the output folder" in line


def test_benchmark_checks_the_tracking_store_and_labels_before_running(generated_maze_dir, tmp_path):
    out = tmp_path / "bench"
    base = ["benchmark", "--maps", str(generated_maze_dir), "--out", str(out)]
    line = _one_error_line(runner.invoke(app, [*base, "--planner", "nearest_frontier", "--tracking-uri", "foo://bar"]))
    assert "not one MLflow 3 can log to" in line
    line = _one_error_line(
        runner.invoke(
            app,
            [*base, "--planner", "nearest_frontier", "--tracking-uri", f"sqlite:///{tmp_path / 'missing' / 'm.db'}"],
        )
    )
    assert "does not exist" in line
    line = _one_error_line(runner.invoke(app, [*base, "--planner", "metrics.csv=nearest_frontier", "--no-mlflow"]))
    assert "name of a benchmark output file" in line
    assert not (out / "metrics.csv").exists()


def test_benchmark_exits_1_when_an_episode_does_not_complete(small_maze_path, tmp_path):
    maps = tmp_path / "maps"
    maps.mkdir()
    (maps / "small.png").write_bytes(small_maze_path.read_bytes())
    result = runner.invoke(
        app,
        [
            "benchmark",
            "--maps",
            str(maps),
            "--planner",
            "nearest_frontier",
            "--no-mlflow",
            "--out",
            str(tmp_path / "b"),
            "--max-steps",
            "2",
            "--workers",
            "1",
        ],
    )
    assert result.exit_code == 1 and "1 of 1 episodes did not complete" in result.output
    assert (tmp_path / "b" / "metrics.csv").is_file()
    assert (
        "warning: small is " in result.output and "; --max-steps 2 suits the benchmark's 100 m mazes" in result.output
    )
    result = runner.invoke(
        app,
        [
            "explore",
            "--map",
            str(maps / "small.png"),
            "--planner",
            "nearest_frontier",
            "--no-progress",
            "--out",
            str(tmp_path / "e"),
            "--max-steps",
            "2",
        ],
    )
    assert result.exit_code == 1 and "raise it with the map's area (e.g. --max-steps 100)" in result.output


def test_a_map_that_cannot_be_completed_is_warned_about(tmp_path):
    grid = np.zeros((60, 60), dtype=np.uint8)
    grid[5:30, 5:30] = 1
    grid[40:58, 40:58] = 1  # 324 free cells the robot can never reach
    np.save(tmp_path / "two_rooms.npy", grid)
    result = runner.invoke(
        app,
        [
            "explore",
            "--map",
            str(tmp_path / "two_rooms.npy"),
            "--start",
            "10",
            "10",
            "--out",
            str(tmp_path / "o"),
            "--no-progress",
            "--node-resolution",
            "2",
            "--sensor-range",
            "8",
        ],
    )
    assert "warning: two_rooms: 324 free cells are not connected to the start" in result.output
    assert result.exit_code == 1  # incomplete, as the warning said


def test_a_map_with_free_cells_no_scan_can_reach_is_warned_about(tmp_path):
    """A pocket that touches the room only at one corner: 8-connected, so not cut off, yet no
    4-connected ray gets in. Explore warns before the episode, benchmark after a failed one."""
    grid = np.zeros((50, 50), dtype=np.uint8)
    grid[5:35, 5:35] = 1
    grid[35:45, 35:45] = 1  # 100 cells
    maps = tmp_path / "maps"
    maps.mkdir()
    np.save(maps / "pocket.npy", grid)
    small = ["--node-resolution", "2", "--sensor-range", "8", "--done-unknown-cells", "20", "--max-steps", "40"]
    result = runner.invoke(
        app,
        [
            "explore",
            "--map",
            str(maps / "pocket.npy"),
            "--start",
            "10",
            "10",
            "--planner",
            "greedy_utility",
            "--out",
            str(tmp_path / "o"),
            "--no-progress",
            *small,
        ],
    )
    warning = "warning: pocket: 100 free cells are seen from no lattice node the robot can reach"
    assert warning in result.output and "raise --done-unknown-cells above 100" in result.output
    assert result.exit_code == 1
    result = runner.invoke(
        app,
        [
            "benchmark",
            "--maps",
            str(maps),
            "--start",
            "10",
            "10",
            "--planner",
            "greedy_utility",
            "--out",
            str(tmp_path / "b"),
            "--no-mlflow",
            "--workers",
            "1",
            *small,
        ],
    )
    assert warning in result.output and result.exit_code == 1
    result = runner.invoke(
        app,
        [
            "explore",
            "--map",
            str(maps / "pocket.npy"),
            "--start",
            "10",
            "10",
            "--planner",
            "greedy_utility",
            "--out",
            str(tmp_path / "o"),
            "--no-progress",
            *small[:4],
            "--done-unknown-cells",
            "120",
        ],
    )
    assert "warning" not in result.output and result.exit_code == 0


def test_explore_warns_before_the_episode_when_a_model_was_trained_at_another_protocol(small_maze_path, tmp_path):
    """The shipped inpainter was trained on a 4 m lattice; a 2 m run goes on, with a one-line warning."""
    import warnings

    from pipeline.cli import warning_line as _warning_line
    from pipeline.world.protocol import ProtocolMismatchWarning

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = runner.invoke(
            app,
            [
                "explore",
                "--map",
                str(small_maze_path),
                "--planner",
                "guide_tsp",
                "--no-progress",
                "--node-resolution",
                "2",
                "--max-steps",
                "3",
                "--out",
                str(tmp_path / "o"),
            ],
        )
    assert result.exit_code == 1 and "step limit" in result.output  # it ran (3 waypoints), the warning stopped nothing
    said = [w for w in caught if issubclass(w.category, ProtocolMismatchWarning)]
    assert said and "inpainter.pt was trained at other protocol values (node_resolution 4 -> 2)" in str(said[0].message)
    line = _warning_line(said[0].message, said[0].category, said[0].filename, said[0].lineno)
    assert line.startswith("warning: ") and line.count("\n") == 1  # as the CLI prints it: no file:line, no source
    assert warnings.formatwarning is not _warning_line  # restored once the command ended


def test_explore_at_the_real_robots_lattice_and_lidar_runs_the_real_robot_models(tmp_path, monkeypatch):
    """`--node-resolution 1 --sensor-range 10` and nothing else: the shipped real-robot models, no warning."""
    from pipeline.world.protocol import ProtocolMismatchWarning

    monkeypatch.chdir(tmp_path)  # no models/ here
    drawn = runner.invoke(
        app,
        [
            "mazes",
            "--kind",
            "office",
            "--scale",
            "real_robot",
            "--cell-size",
            "0.2",
            "--side",
            "20",
            "--count",
            "1",
            "--seed",
            "3",
            "--out",
            "floors",
        ],
    )
    assert drawn.exit_code == 0, drawn.output
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = runner.invoke(
            app,
            [
                "explore",
                "--map",
                "floors/office_0000.png",
                "--planner",
                "guide",
                "--no-progress",
                "--cell-size",
                "0.2",
                "--node-resolution",
                "1",
                "--sensor-range",
                "10",
                "--done-unknown-cells",
                "1000",
                "--out",
                "o",
            ],
        )
    assert result.exit_code == 0, result.output
    assert not [w for w in caught if issubclass(w.category, ProtocolMismatchWarning)]
    assert "assets/real_robot/inpainter.pt" in result.output  # the description printed before the episode
    record = json.loads((tmp_path / "o" / "run.json").read_text())
    assert record["protocol"]["region_size"] == 10.0 and record["protocol"]["utility_range"] == 5.0
    assert "assets/real_robot/" in record["planner"]["description"]


def test_maps_with_one_name_are_refused(small_maze_path, tmp_path):
    import shutil

    from pipeline.evaluation.benchmark import MapSet
    from pipeline.world.map_files import MapError
    from pipeline.world.protocol import Protocol

    for name in ("a.png", "b.png", "c/a.png"):
        (tmp_path / name).parent.mkdir(exist_ok=True)
        shutil.copy(small_maze_path, tmp_path / name)
    assert set(MapSet.of([tmp_path / "a.png", tmp_path / "b.png"], Protocol(), None).loaded) == {"a", "b"}
    with pytest.raises(MapError, match="same name 'a'.*overwrite"):
        MapSet.of([tmp_path / "a.png", tmp_path / "c" / "a.png"], Protocol(), None).loaded


def test_tracking_store_check():
    from pipeline.common.mlflow_store import check_tracking_uri

    assert check_tracking_uri("sqlite:///mlflow.db") == "sqlite:///mlflow.db"
    with pytest.raises(ValueError, match="no MLflow server answers"):
        check_tracking_uri("http://127.0.0.1:9", timeout_s=2)  # port 9 (discard): nothing listens
    with pytest.raises(ValueError, match="not one MLflow 3 can log to"):
        check_tracking_uri("./mlruns")


def test_eval_predictor_takes_a_start_for_grids_without_one(small_maze, tmp_path):
    """A .npy grid has no start of its own: --start gives it, as for explore and benchmark."""
    grids = tmp_path / "grids"
    grids.mkdir()
    np.save(grids / "small.npy", small_maze.free.astype(np.uint8))
    out = tmp_path / "p"
    line = _one_error_line(runner.invoke(app, ["eval-predictor", "--maps", str(grids), "--out", str(out)]))
    assert "needs its start cell" in line
    col, row = small_maze.start_cell
    result = runner.invoke(
        app, ["eval-predictor", "--maps", str(grids), "--out", str(out), "--start", str(col), str(row)]
    )
    assert result.exit_code == 0, result.output
    frame = pd.read_csv(out / "precision.csv")
    assert frame["maps"].max() == 1


def test_replay_of_a_run_made_from_another_start_points_to_its_start(small_maze_path, small_maze, tmp_path):
    col, row = small_maze.start_cell
    start = next(
        (c, r) for c, r in ((col + 10, row), (col, row + 10), (col - 10, row), (col, row - 10)) if small_maze.free[r, c]
    )
    out = tmp_path / "moved"
    explored = runner.invoke(
        app,
        [
            "explore",
            "--map",
            str(small_maze_path),
            "--start",
            str(start[0]),
            str(start[1]),
            "--out",
            str(out),
            "--no-progress",
        ],
    )
    assert explored.exit_code == 0, explored.output
    trajectory = ["--trajectory", str(out / "small.csv")]
    result = runner.invoke(app, ["replay", "--map", str(small_maze_path), *trajectory])
    assert result.exit_code == 1
    assert f"says the run started at --start {start[0]} {start[1]}; replay it with the same --start" in result.output
    again = runner.invoke(
        app, ["replay", "--map", str(small_maze_path), *trajectory, "--start", str(start[0]), str(start[1])]
    )
    assert again.exit_code == 0 and json.loads(again.output)["complete"]


def test_mazes_options_are_named_in_their_errors(tmp_path):
    def error(*options: str) -> str:
        return _one_error_line(runner.invoke(app, ["mazes", "--out", str(tmp_path / "m"), "--count", "1", *options]))

    assert error("--side", "0") == "error: --side must be a positive number of metres, got 0"
    assert error("--side", "nan") == "error: --side must be a positive number of metres, got nan"
    assert "--side 5 allows a side of 1 block; a maze needs at least" in error("--side", "5")
    line = error("--cell-size", "0.3")
    assert line.startswith("error: --cell-size 0.3 does not fit the mazes' 5 m blocks") and "MazeConfig" not in line
    assert not (tmp_path / "m").exists()


def test_eval_predictor_says_when_no_exploration_reaches_a_step(tmp_path):
    maps = tmp_path / "rooms"
    maps.mkdir()
    write_maze_png(maze_from_blocks(["######", "#S...#", "#....#", "######"]), maps / "room.png")  # seen at once
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = runner.invoke(app, ["eval-predictor", "--maps", str(maps), "--out", str(tmp_path / "p")])
    assert result.exit_code == 0, result.output
    said = [str(w.message) for w in caught]
    assert any(
        m.startswith("no exploration reached step 15, 30, 45, 60: every episode completed earlier") for m in said
    )
    assert any(m.startswith("fig3.png not drawn") for m in said)
    assert pd.read_csv(tmp_path / "p" / "precision.csv")["maps"].eq(0).all()
    nan = runner.invoke(
        app, ["eval-predictor", "--maps", str(maps), "--out", str(tmp_path / "q"), "--threshold", "nan"]
    )
    assert _one_error_line(nan) == "error: --threshold must be a probability in [0, 1], got nan"


def test_explore_prints_every_model_file_the_planner_runs(small_maze_path, tmp_path):
    result = runner.invoke(
        app,
        [
            "explore",
            "--map",
            str(small_maze_path),
            "--planner",
            "guide_tsp",
            "--out",
            str(tmp_path / "o"),
            "--max-steps",
            "2",
            "--no-progress",
        ],
    )
    (line,) = [line for line in result.output.splitlines() if line.startswith("models: ")]
    files = line.removeprefix("models: ").split(", ")
    assert [name.rsplit("/", 1)[-1] for name in files] == ["inpainter.pt", "sliver_gate.json"]
    plain = runner.invoke(
        app,
        [
            "explore",
            "--map",
            str(small_maze_path),
            "--planner",
            "nearest_frontier",
            "--out",
            str(tmp_path / "p"),
            "--max-steps",
            "2",
            "--no-progress",
        ],
    )
    assert "models: " not in plain.output  # no trained model: no line


def test_planners_options_says_what_guide_is_built_of():
    result = runner.invoke(app, ["planners", "--options", "guide"])
    assert result.exit_code == 0
    (line,) = [line for line in result.output.splitlines() if "built as:" in line]
    assert "tour vote" in line and "guide/guide.py" in line
    names = [
        line.split(" = ")[0].strip() for line in result.output.splitlines() if line.startswith("  ") and " = " in line
    ]
    assert names[:2] == ["min_utility", "inpainter_file"] and "policy_file" in names[:8]  # the paper's options first
    parts = [line[4:] for line in result.output.splitlines() if line.startswith("  # ")]
    assert parts[:4] == [
        "targets on the lattice (Sec. IV-A)",
        "the node predictor (Sec. IV-B)",
        "the global graph (Sec. IV-B)",
        "the diffusion policy (Sec. IV-C)",
    ]
    assert {
        "the tour vote (ours, mode tour)",
        "the lookahead (ours, mode tour)",
        "trust in the predictions (ours)",
    } <= set(parts)
    lines = result.output.splitlines()
    vote = lines.index("  # the tour vote (ours, mode tour)")
    assert lines[vote + 1].startswith("  prior_weight = ")  # each option under the part that declares it
    greedy = runner.invoke(app, ["planners", "--options", "greedy_utility"]).output
    assert "  # the sliver gate (ours)" in greedy and "  sliver_gate = false" in greedy
    tare = runner.invoke(app, ["planners", "--options", "tare"]).output
    assert "  # tare's own" in tare


def test_planners_options_prints_each_protocols_defaults():
    maze = runner.invoke(app, ["planners", "--options", "guide", "--protocol", "maze"])
    assert maze.exit_code == 0, maze.output
    assert "defaults at protocol maze (5 differ" in maze.output
    assert "  spread = None *" in maze.output and "  min_weight = 30.0 *" in maze.output
    real = runner.invoke(app, ["planners", "--options", "guide", "--protocol", "real_robot"])
    assert "(the config's own)" in real.output and "  spread = 0.0\n" in real.output and " *" not in real.output
    plain = runner.invoke(app, ["planners", "--options", "guide"])
    assert "  spread = 0.0   (maze: None)" in plain.output
    unknown = runner.invoke(app, ["planners", "--options", "guide", "--protocol", "moon"])
    assert unknown.exit_code == 2 and "unknown protocol 'moon'" in _one_error_line(unknown)
    alone = runner.invoke(app, ["planners", "--protocol", "maze"])
    assert alone.exit_code == 2 and "--protocol goes with --options" in _one_error_line(alone)


def test_explore_with_a_predicting_planner_records_its_trust(small_maze_path, tmp_path):
    """run.json holds the record of checked predictions, the per-step file the trust at each
    waypoint, and the final figure a trust strip under the map."""
    from pipeline.world.trajectories import read_steps_csv

    out = tmp_path / "trust"
    result = runner.invoke(app, ["explore", "--map", str(small_maze_path), "--planner", "guide_tsp", "--out", str(out)])
    assert result.exit_code == 0, result.output
    record = json.loads((out / "run.json").read_text())["prediction_trust"]
    assert record["right"] + record["wrong"] > 0 and 0.0 <= record["trust"] <= 1.0
    steps = read_steps_csv(out / "small.steps.csv")
    assert np.isnan(steps["prediction_trust"][0]) and np.isfinite(steps["prediction_trust"][1:]).all()
    plain = tmp_path / "plain"
    assert (
        runner.invoke(
            app,
            ["explore", "--map", str(small_maze_path), "--planner", "plain=guide_tsp:trust=false", "--out", str(plain)],
        ).exit_code
        == 0
    )
    assert "prediction_trust" not in json.loads((plain / "run.json").read_text())
    taller = cv2.imread(str(out / "small.png")).shape[0] - cv2.imread(str(plain / "small.png")).shape[0]
    assert taller > 0  # the trust strip


def test_plans_import_writes_a_family_the_benchmark_reads_and_refuses_bad_input(tmp_path):
    from pipeline.world.maps import load_map

    image = np.zeros((100, 190), np.uint8)
    image[10:90, 10:90] = 255
    image[10:90, 93:180] = 255
    image[40:52, 90:93] = 255
    src = tmp_path / "plans"
    src.mkdir()
    cv2.imwrite(str(src / "floor.png"), image)
    out = tmp_path / "family"
    result = CliRunner().invoke(app, ["plans", "import", str(src), "--out", str(out), "--resolution", "0.05"])
    assert result.exit_code == 0, result.output
    assert "wrote 1 plan" in result.output and (out / "manifest.json").is_file()
    assert load_map(out / "floor.yaml").cell_size == pytest.approx(0.2)
    (src / "broken.png").write_bytes(b"not an image")
    again = CliRunner().invoke(
        app, ["plans", "import", str(src), "--out", str(tmp_path / "other"), "--resolution", "0.05"]
    )
    assert again.exit_code == 2
    assert again.output.strip().splitlines()[-1].startswith(f"error: {src / 'broken.png'}: not a readable image")
    assert not (tmp_path / "other").exists()  # nothing half-written
    unresolved = CliRunner().invoke(app, ["plans", "import", str(src / "floor.png"), "--out", str(tmp_path / "x")])
    assert unresolved.exit_code == 2 and "no resolution" in unresolved.output
