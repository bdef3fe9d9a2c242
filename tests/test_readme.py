"""The README's quick start runs as written (its `guide` commands; `dvc repro` is the end-to-end
test's, and `mlflow ui` starts a server), and its links and commands point at what exists."""

from __future__ import annotations

import re
import shlex

from import_graph import ROOT
from typer.testing import CliRunner

from pipeline.cli import COMMANDS, app

README = (ROOT / "README.md").read_text()


def quick_start_commands() -> list[list[str]]:
    block = README.split("## Quick start", 1)[1].split("```bash", 1)[1].split("```", 1)[0]
    lines = [line.split("#", 1)[0].strip() for line in block.splitlines()]
    return [shlex.split(line) for line in lines if line]


def test_the_quick_start_runs_as_written(tmp_path, monkeypatch, mlflow_uri):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MLFLOW_TRACKING_URI", mlflow_uri)
    commands = quick_start_commands()
    assert [c[0] for c in commands] == ["guide"] * 4 + ["dvc", "mlflow"]
    runner = CliRunner()
    for command in commands[:4]:
        result = runner.invoke(app, command[1:])
        assert result.exit_code == 0, (command, result.output)
    assert (tmp_path / "runs/explore/guide/maze_0000.gif").is_file()
    summary = (tmp_path / "runs/bench/summary.md").read_text()
    assert "| guide |" in summary and "| greedy_utility |" in summary


def test_the_readme_stays_a_users_page():
    lines = README.splitlines()
    assert len(lines) <= 250
    assert not re.search(r"\b[0-9a-f]{7,40}\b", README.replace("sqlite:///mlflow.db", "")), "a commit hash"
    for link in re.findall(r"\]\(([^)#]+)", README):
        if not link.startswith("http"):
            assert (ROOT / link).exists(), link
    for command in re.findall(r"^guide ([a-z-]+)", README, flags=re.M):
        assert command in COMMANDS, command


def _guide_commands(text: str) -> list[list[str]]:
    blocks = re.findall(r"```bash\n(.*?)```", text, flags=re.S)
    lines = [line.split("  #", 1)[0].strip() for block in blocks for line in block.splitlines()]
    return [shlex.split(line) for line in lines if line.startswith("guide ")]


def test_every_guide_command_in_the_docs_parses():
    """Each `guide` command of README.md and docs/cli.md names a command and options that exist,
    with values of the right kind (parsed, not run: the quick start above runs for real)."""
    import click
    import typer

    group = typer.main.get_group(app)
    commands = _guide_commands(README) + _guide_commands((ROOT / "docs" / "cli.md").read_text())
    assert len(commands) >= 15
    for argv in commands:
        with click.Context(group) as root:
            command = group.get_command(root, argv[1])
            assert command is not None, argv
            command.make_context(argv[1], argv[2:], parent=root)  # raises on an unknown option or a bad value
