"""Stages run as `python -m stages.<name>` (what `dvc repro` runs) fail on user errors with one line."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest
from import_graph import ROOT

from pipeline.planners.registry import UnknownPlannerError
from pipeline.stage_runner import UPSTREAM_HINT, run_stage_main, user_error_message
from pipeline.world.map_files import MapError


@pytest.mark.parametrize(
    "error, message",
    [
        (FileNotFoundError("data/mazes/test: not a directory"), "data/mazes/test: not a directory" + UPSTREAM_HINT),
        (
            FileNotFoundError("models/x.pt: no export; run the train stage first"),
            "models/x.pt: no export; run the train stage first",
        ),
        (FileNotFoundError("my.png not found"), "my.png not found"),
        (MapError("a.png", "no free cell"), "a.png: no free cell"),
        (ValueError("tau must be in (0, 1)"), "tau must be in (0, 1)"),
        (SystemExit("error: nothing to do"), "nothing to do"),
        (SystemExit(0), None),
        (UnknownPlannerError("unknown planner 'foo'; choose from: dare"), "unknown planner 'foo'; choose from: dare"),
        (KeyError("bug"), None),
        (ZeroDivisionError(), None),
    ],
)
def test_user_error_message(error, message):
    assert user_error_message(error) == message


def test_run_stage_main_prints_one_line_and_exits_2(capsys):
    def missing(path):
        raise FileNotFoundError(f"{path}: not a directory")

    with pytest.raises(SystemExit) as exit_info:
        run_stage_main(missing, "data/mazes/train")
    assert exit_info.value.code == 2
    assert capsys.readouterr().err == f"error: data/mazes/train: not a directory{UPSTREAM_HINT}\n"
    assert run_stage_main(lambda a, b: a + b, 2, 3) == 5
    with pytest.raises(KeyError):  # a bug keeps its traceback
        run_stage_main(lambda: {}["x"])


def test_python_m_stage_without_inputs_is_one_error_line(tmp_path):
    (tmp_path / "params.yaml").write_text((ROOT / "params.yaml").read_text())
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run(
        [sys.executable, "-m", "stages.train_planner"],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip().splitlines() == [
        "error: data/observations/guide.npz: no observations; run the build_observations stage first"
    ]


def stage_error(capsys, stage, *args) -> str:
    """The one `error:` line a stage's main prints through `run_stage_main` (exit status 2)."""
    with pytest.raises(SystemExit) as exit_info:
        run_stage_main(stage.main, *args)
    assert exit_info.value.code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), lines
    return lines[0]


def test_stages_without_their_inputs_print_one_line(tmp_path, monkeypatch, capsys):
    from stages import benchmark, generate_mazes, train_planner

    monkeypatch.chdir(tmp_path)  # a fresh folder: no params.yaml, no data
    assert "nope.yaml" in stage_error(capsys, generate_mazes, "nope.yaml")
    (tmp_path / "params.yaml").write_text(
        "protocol: {}\nbenchmark: {planners: [nearest_frontier], seed: 0, workers: 1, speed_mps: 2.0}\n"
    )
    line = stage_error(capsys, benchmark, "params.yaml")
    assert "data/mazes/test" in line and "dvc repro" in line
    (tmp_path / "params.yaml").write_text((ROOT / "params.yaml").read_text())
    assert "no observations; run the build_observations stage first" in stage_error(
        capsys, train_planner, "params.yaml", "dare"
    )


def test_stage_params_that_are_not_a_params_file_are_one_error_line(tmp_path, monkeypatch, capsys):
    from stages import collect_expert, generate_mazes, train_planner

    monkeypatch.chdir(tmp_path)
    (tmp_path / "README.md").write_text("# guide\n\n*GUIDE: a paper*\n")  # not YAML: '*' starts an alias
    for stage in (generate_mazes, collect_expert, train_planner):
        line = stage_error(capsys, stage, "README.md")
        assert "README.md: not valid YAML" in line and "line 3, column 1" in line
    (tmp_path / "bare.yaml").write_text("protocol: {}\n")
    assert stage_error(capsys, collect_expert, "bare.yaml") == "error: bare.yaml: missing the 'collect_expert' section"


def test_benchmark_stage_settings_are_checked_before_any_episode(generated_maze_dir, tmp_path, monkeypatch, capsys):
    import shutil

    from stages import benchmark

    monkeypatch.chdir(tmp_path)
    shutil.copytree(generated_maze_dir, tmp_path / "data" / "mazes" / "test")
    (tmp_path / "p.yaml").write_text(
        "protocol: {}\nbenchmark: {planners: [nearest_frontier, foo], seed: 0, workers: 1, speed_mps: 2.0}\n"
    )
    line = stage_error(capsys, benchmark, "p.yaml")
    assert (
        line.startswith("error: p.yaml: benchmark.planners[1]: ")
        and "unknown planner 'foo'" in line
        and "nearest_frontier" in line
    )
    (tmp_path / "w.yaml").write_text(
        "protocol: {}\nbenchmark: {planners: [nearest_frontier], seed: 0, workers: 0, speed_mps: 2}\n"
    )
    assert (
        stage_error(capsys, benchmark, "w.yaml")
        == "error: w.yaml: benchmark.workers: must be a whole number >= 1, or null (all cores), got 0"
    )
    (tmp_path / "r.yaml").write_text(
        "protocol: {}\nbenchmark: {planners: [nearest_frontier], seed: 0, workers: 1, speed_mps: 2,"
        " robots: [1, 9], team_planners: [greedy_utility]}\n"
    )
    assert stage_error(capsys, benchmark, "r.yaml").startswith(
        "error: r.yaml: benchmark.robots[1]: must be a whole number"
    )
    (tmp_path / "t.yaml").write_text(
        "protocol: {}\nbenchmark: {planners: [nearest_frontier], seed: 0, workers: 1, speed_mps: 2,"
        " robots: [3], team_planners: [uncoordinated_foo]}\n"
    )
    line = stage_error(capsys, benchmark, "t.yaml")
    assert line.startswith("error: t.yaml: benchmark.team_planners[0]: ") and "uncoordinated_foo" in line
    (tmp_path / "s.yaml").write_text(
        "protocol: {}\nbenchmark: {planners: [nearest_frontier], seed: 0, workers: 1, speed_mps: -2}\n"
    )
    assert (
        stage_error(capsys, benchmark, "s.yaml")
        == "error: s.yaml: benchmark.speed_mps: must be a finite number > 0 (metres per second), got -2"
    )
    assert not (tmp_path / "reports" / "benchmark").exists()


def test_train_planner_refuses_zero_epochs_before_touching_its_checkpoints(tmp_path, monkeypatch, capsys):
    from stages import train_planner

    monkeypatch.chdir(tmp_path)
    (tmp_path / "params.yaml").write_text((ROOT / "params.yaml").read_text())
    for epochs in (0, -1):  # 0 would export an untrained policy over a trained one
        line = stage_error(capsys, train_planner, "params.yaml", "guide", None, None, False, epochs)
        assert line == f"error: train_planner.train.max_epochs: must be a whole number >= 1, got {epochs}"


def test_every_stage_takes_params_and_says_what_it_does():
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    for stage in sorted(path.stem for path in (ROOT / "stages").glob("*.py") if path.stem != "__init__"):
        done = subprocess.run(
            [sys.executable, "-m", f"stages.{stage}", "--help"],
            cwd=ROOT,
            env=env,
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert done.returncode == 0 and "--params" in done.stdout, (stage, done.stderr)
