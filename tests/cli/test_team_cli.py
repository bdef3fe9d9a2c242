import json

import pandas as pd
import pytest
from typer.testing import CliRunner

from pipeline.cli import app

runner = CliRunner()
EXPERIMENT = "team-cli-test"


def one_error_line(result) -> str:
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    lines = [line for line in result.output.strip().splitlines() if line]
    assert len(lines) == 1 and lines[0].startswith("error: "), result.output
    return lines[0]


def run_team_cli(maps, out, *extra):
    return runner.invoke(
        app,
        [
            "benchmark",
            "--maps",
            str(maps),
            "--planner",
            "uncoordinated_greedy_utility",
            "--planner",
            "nf=uncoordinated_nearest_frontier",
            "--out",
            str(out),
            *extra,
        ],
    )


def test_benchmark_with_robots_writes_team_files_that_replay_and_logs_one_run_per_count(
    generated_maze_dir, tmp_path, mlflow_uri
):
    import mlflow

    mlflow.MlflowClient(tracking_uri=mlflow_uri).create_experiment(
        EXPERIMENT, artifact_location=(tmp_path / "artifacts").as_uri()
    )
    out = tmp_path / "team"
    result = run_team_cli(
        generated_maze_dir,
        out,
        "--robots",
        "1",
        "--robots",
        "2",
        "--workers",
        "2",
        "--tracking-uri",
        mlflow_uri,
        "--experiment",
        EXPERIMENT,
    )
    assert result.exit_code == 0, result.output
    assert "| nf@2 | 2 | 3 |" in result.output and "12 team trajectories" in result.output
    for name in ("team_metrics.csv", "team_coverage.csv", "team_summary.json", "team_run.json", "team_coverage.png"):
        assert (out / name).is_file(), name
    assert not (out / "metrics.csv").exists()  # the single-robot benchmark's files are not written
    run_labels = ["nf@1", "nf@2", "uncoordinated_greedy_utility@1", "uncoordinated_greedy_utility@2"]
    assert sorted(json.loads((out / "team_summary.json").read_text())) == run_labels
    for label in run_labels:
        assert (out / label / "maze_0000.team.png").is_file()  # the first map's paths
        for number in range(3):
            team_file = out / label / f"maze_{number:04d}.team.csv"
            replayed = runner.invoke(
                app,
                ["replay", "--map", str(generated_maze_dir / f"maze_{number:04d}.png"), "--trajectory", str(team_file)],
            )
            assert replayed.exit_code == 0, replayed.output
            figures = json.loads(replayed.output)
            assert figures["complete"] and figures["robots"] == int(label[-1]) and figures["motion_violations"] == 0
            assert len(figures["robot_distance_m"]) == figures["robots"] and figures["makespan_s"] > 0

    mlflow.set_tracking_uri(mlflow_uri)
    runs = mlflow.search_runs(experiment_names=[EXPERIMENT]).set_index("tags.mlflow.runName")
    assert sorted(runs.index) == run_labels
    assert list(runs.loc[run_labels, "params.robots"]) == ["1", "2", "1", "2"]
    assert runs.loc["nf@2", "params.planner_name"] == "uncoordinated_nearest_frontier"
    assert (runs["metrics.completion_rate"] == 1.0).all()
    assert runs.loc["nf@1", "metrics.makespan_over_single_distance"] == 1.0
    assert runs["metrics.makespan_mean_m"].notna().all()


def test_comm_range_writes_the_merges_files(generated_maze_dir, tmp_path):
    out = tmp_path / "range"
    result = run_team_cli(
        generated_maze_dir, out, "--robots", "3", "--comm-range", "12", "--workers", "1", "--no-mlflow"
    )
    assert result.exit_code == 0, result.output
    merges = sorted(out.glob("*/*.team.merges.csv"))
    assert len(merges) == 6 and all(len(pd.read_csv(path)) > 0 for path in merges)
    assert (pd.read_csv(out / "team_metrics.csv")["comm_range_m"] == 12).all()


@pytest.mark.parametrize(
    "flags, message",
    [
        (["--robots", "0"], "--robots takes team sizes 1-8, got 0"),
        (["--robots", "2", "--robots", "9"], "--robots takes team sizes 1-8, got 2, 9"),
        (["--robots", "3", "--comm-range", "0"], "--comm-range takes a positive number of metres, got 0"),
        (["--robots", "3", "--comm-range", "-5"], "--comm-range takes a positive number of metres, got -5"),
        (["--comm-range", "10"], "--comm-range is the range of a team's radios: give the team size with --robots"),
        (["--robots", "2", "--baseline", "nf"], "--baseline compares single-robot planners"),
    ],
)
def test_bad_team_flags_are_refused_in_one_line_before_any_work(generated_maze_dir, tmp_path, flags, message):
    out = tmp_path / "never"
    line = one_error_line(run_team_cli(generated_maze_dir, out, *flags, "--no-mlflow"))
    assert message in line
    assert not out.exists()


def test_a_planner_no_team_can_run_is_refused_in_one_line(generated_maze_dir, tmp_path):
    result = runner.invoke(
        app,
        [
            "benchmark",
            "--maps",
            str(generated_maze_dir),
            "--planner",
            "expert",
            "--robots",
            "2",
            "--out",
            str(tmp_path / "o"),
            "--no-mlflow",
        ],
    )
    assert "planner 'expert'" in one_error_line(result)
    result = runner.invoke(
        app,
        [
            "benchmark",
            "--maps",
            str(generated_maze_dir),
            "--planner",
            "nope",
            "--robots",
            "2",
            "--out",
            str(tmp_path / "o"),
            "--no-mlflow",
        ],
    )
    assert "unknown team planner 'nope'" in one_error_line(result)


def test_an_interrupted_team_benchmark_says_how_to_resume(generated_maze_dir, tmp_path, monkeypatch):
    import pipeline.evaluation.team_benchmark as team_benchmark

    finished = team_benchmark.run_team_task

    def interrupt_after_the_first(inputs, task):
        if interrupt_after_the_first.calls:
            raise KeyboardInterrupt
        interrupt_after_the_first.calls += 1
        return finished(inputs, task)

    interrupt_after_the_first.calls = 0
    monkeypatch.setattr(team_benchmark, "run_team_task", interrupt_after_the_first)
    out = tmp_path / "cut"
    result = runner.invoke(
        app,
        [
            "benchmark",
            "--maps",
            str(generated_maze_dir),
            "--planner",
            "nf=uncoordinated_nearest_frontier",
            "--robots",
            "2",
            "--out",
            str(out),
            "--workers",
            "1",
            "--no-mlflow",
        ],
    )
    assert result.exit_code == 130
    assert f"interrupted after 1 of 3 team episodes; {out}/team_metrics.csv holds them" in result.output
    assert len(pd.read_csv(out / "team_metrics.csv")) == 1


def test_replay_of_a_team_file_that_breaks_the_rule_or_stops_early_exits_1(generated_maze_dir, tmp_path):
    maze = str(generated_maze_dir / "maze_0000.png")
    jump = tmp_path / "jump.team.csv"
    jump.write_text("time_s,robot,x,y\n0,0,0,0\n0,1,0,0\n1,1,40,0\n")
    result = runner.invoke(app, ["replay", "--map", maze, "--trajectory", str(jump)])
    figures = json.loads(result.output)
    assert result.exit_code == 1 and figures["motion_violations"] == 1 and "robot 1" in figures["failure"]
    early = tmp_path / "early.team.csv"
    early.write_text("time_s,robot,x,y\n0,0,0,0\n0,1,0,0\n")
    result = runner.invoke(app, ["replay", "--map", maze, "--trajectory", str(early)])
    figures = json.loads(result.output)
    assert result.exit_code == 1 and not figures["complete"] and figures["robots"] == 2
    assert "--steps-csv is a single robot's" in one_error_line(
        runner.invoke(
            app, ["replay", "--map", maze, "--trajectory", str(early), "--steps-csv", str(tmp_path / "s.csv")]
        )
    )
    assert "robot must be a whole number 0-7" in one_error_line(
        runner.invoke(
            app, ["replay", "--map", maze, "--trajectory", str(_written(tmp_path / "nine.team.csv", "0,9,0,0"))]
        )
    )


def _written(path, line):
    path.write_text(f"time_s,robot,x,y\n{line}\n")
    return path
