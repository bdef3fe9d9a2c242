"""The train_drl DVC stage on a tiny policy and 50 m mazes: what it writes, resuming from its
checkpoint (and training afresh when the settings changed), its MLflow run, and its refusal
of bad settings."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import pytest
import torch
import yaml

from pipeline.models.modeling_drl import load_drl_policy
from pipeline.workflows import train_drl as train_drl_workflow
from pipeline.world.protocol import Protocol
from stages import train_drl

ROOT = Path(__file__).resolve().parents[2]
PROTOCOL = {"max_steps": 80}  # the evaluation's episodes: the drl policy's and nearest_frontier's


def tiny_section() -> dict:
    """The project's train_drl section, shrunk to seconds."""
    section = copy.deepcopy(yaml.safe_load((ROOT / "params.yaml").read_text())["train_drl"])
    section["model"].update(max_nodes=32, d_model=16, heads=2, encoder_layers=1)
    section["env"].update(maze_sides_m=[50], max_steps=30)
    section["ppo"].update(n_envs=2, n_steps=32, batch_size=32, n_epochs=1)
    section["imitation"].update(episodes=2, epochs=1, dagger_rounds=1, dagger_episodes=1, dagger_epochs=1)
    section.update(timesteps=64, checkpoint_every=32, eval_mazes=1, eval_side_m=50, threads=1)
    return section


def write_params(folder: Path, section: dict, protocol: dict = PROTOCOL) -> None:
    (folder / "params.yaml").write_text(yaml.safe_dump({"protocol": protocol, "train_drl": section}))


@pytest.fixture
def project(tmp_path, monkeypatch, mlflow_uri):
    """A project folder with the tiny params.yaml, logging to the session's MLflow store."""
    import mlflow

    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MLFLOW_TRACKING_URI", mlflow_uri)
    client = mlflow.MlflowClient(tracking_uri=mlflow_uri)
    experiment = tiny_section()["experiment"]
    if client.get_experiment_by_name(experiment) is None:  # its artifacts beside the store, not in ./mlruns
        folder = Path(mlflow_uri.removeprefix("sqlite:///")).parent
        client.create_experiment(experiment, artifact_location=(folder / "artifacts" / experiment).as_uri())
    write_params(tmp_path, tiny_section())
    return tmp_path, client, client.get_experiment_by_name(experiment).experiment_id


def test_the_stage_trains_exports_evaluates_resumes_and_logs(project, capsys):
    folder, client, experiment_id = project
    runs_before = len(client.search_runs([experiment_id]))

    metrics = train_drl.main("params.yaml")
    first = capsys.readouterr().out
    assert "training afresh" not in first and "continuing" not in first  # no checkpoint yet
    policy, trained_on = load_drl_policy(folder / "models/drl/policy.pt")
    assert policy.config.max_nodes == 32 and policy.config.d_model == 16 and not policy.training
    assert trained_on["protocol"] == Protocol(max_steps=80).to_dict()
    assert trained_on["timesteps"] == 64 and trained_on["seed"] == tiny_section()["seed"]
    assert trained_on["env"]["maze_sides_m"] == [50.0] and trained_on["ppo"]["n_steps"] == 32
    written = json.loads((folder / "reports/drl_metrics.json").read_text())
    assert written == metrics
    assert metrics["timesteps"] == 64 and metrics["resumed_from"] == 0
    assert metrics["parameters"] == sum(p.numel() for p in policy.parameters())
    assert [row["timesteps"] for row in metrics["history"]] == [64.0]
    evaluation = metrics["evaluation"]
    assert evaluation["mazes"] == 1 and evaluation["side_m"] == 50 and len(evaluation["episodes"]) == 1
    assert evaluation["completed"] in (0, 1) and evaluation["distance_m"] > 0
    assert evaluation["nearest_frontier_distance_m"] > 0
    assert evaluation["distance_m"] == pytest.approx(evaluation["episodes"][0]["distance"], abs=0.06)
    assert (folder / "reports/drl_curves.png").stat().st_size > 5000
    record = json.loads((folder / "checkpoints/drl/last.json").read_text())
    assert record["timesteps"] == 64 and len(record["history"]) == 1 and record["fingerprint"]
    assert (folder / "checkpoints/drl/last.zip").stat().st_size > 0
    assert not list((folder / "checkpoints/drl").glob(".last.*"))  # written atomically, no leftovers

    runs = client.search_runs([experiment_id], order_by=["attribute.start_time DESC"])
    assert len(runs) == runs_before + 1
    assert runs[0].data.metrics["timesteps"] == 64 and runs[0].data.params["ppo.n_envs"] == "2"
    inputs = {i.dataset.name: i for i in runs[0].inputs.dataset_inputs}  # the mazes drawn, by their settings
    assert len(inputs) == 2 and all(i.dataset.source_type == "code" and i.dataset.digest for i in inputs.values())
    assert runs[0].data.metrics["eval_distance_m"] == evaluation["distance_m"]

    # Longer: continues from the checkpoint, whatever timesteps says.
    metrics = train_drl.main("params.yaml", timesteps=128)
    assert "continuing from the checkpoint at 64 of 128 steps" in capsys.readouterr().out
    assert metrics["resumed_from"] == 64 and metrics["timesteps"] == 128
    assert [row["timesteps"] for row in metrics["history"]] == [64.0, 128.0]
    assert load_drl_policy(folder / "models/drl/policy.pt")[1]["timesteps"] == 128
    assert json.loads((folder / "checkpoints/drl/last.json").read_text())["timesteps"] == 128

    # Other PPO settings: the checkpoint is not theirs.
    section = tiny_section()
    section["ppo"]["learning_rate"] = 0.001
    write_params(folder, section)
    metrics = train_drl.main("params.yaml")
    assert "made with other settings; training afresh" in capsys.readouterr().out
    assert metrics["resumed_from"] == 0 and metrics["timesteps"] == 64
    assert len(client.search_runs([experiment_id])) == runs_before + 3


def test_a_checkpoint_at_another_protocol_or_past_the_steps_asked_is_not_continued(project, capsys):
    folder, _, _ = project
    section = tiny_section()
    section["eval_mazes"] = 0  # no evaluation: none is written
    write_params(folder, section)
    assert train_drl.main("params.yaml")["evaluation"] == {}
    capsys.readouterr()
    # The evaluation and the checkpoint interval are not what the weights depend on: continued.
    write_params(folder, {**section, "eval_side_m": 60, "checkpoint_every": 64})
    assert train_drl.main("params.yaml")["resumed_from"] == 64
    assert "continuing from the checkpoint at 64" in capsys.readouterr().out
    # A checkpoint further in than the run asks for.
    metrics = train_drl.main("params.yaml", timesteps=32)
    assert "past the 32 asked for; training afresh" in capsys.readouterr().out
    # PPO learns whole rollouts (2 x 32 steps): the steps done are recorded, not those asked for.
    assert metrics["resumed_from"] == 0 and metrics["timesteps"] == 64
    assert load_drl_policy(folder / "models/drl/policy.pt")[1]["timesteps"] == 64
    # The protocol is part of what the weights depend on.
    write_params(folder, section, {**PROTOCOL, "sensor_range": 15.0})
    assert train_drl.main("params.yaml")["resumed_from"] == 0
    assert "made with other settings; training afresh" in capsys.readouterr().out
    # An unreadable record.
    (folder / "checkpoints/drl/last.json").write_text("{not json")
    assert train_drl.main("params.yaml")["resumed_from"] == 0
    assert "unreadable; training afresh" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"timesteps": 0}, r"train_drl\.timesteps: must be a whole number >= 1"),
        ({"checkpoint_every": 2.5}, r"train_drl\.checkpoint_every: must be a whole number >= 1"),
        ({"eval_mazes": -1}, r"train_drl\.eval_mazes: must be a whole number >= 0"),
        (
            {"model": {"max_nodes": 32, "d_model": 16, "heads": 3}},
            r"train_drl.model: .*heads \(3\) must divide d_model \(16\)",
        ),
        (
            {"model": {"layers": 2}},
            r"train_drl\.model\.layers: unknown setting \(known: feature_dim, max_nodes, max_neighbors, d_model, heads, encoder_layers, window_scale, logit_clip, guidepost_prior\)",
        ),
        ({"model": [16]}, r"train_drl\.model: must be a mapping of DRLPolicyConfig settings, got \[16\]"),
        ({"env": {"maze_sides_m": [52]}}, r"train_drl.env.maze_sides_m: maze_side_m 52"),
        ({"env": {"max_steps": 0}}, r"train_drl\.env\.max_steps: must be a whole number >= 1"),
        ({"env": {"area_weight": -1.0}}, r"train_drl\.env\.area_weight: must be a finite number >= 0"),
        ({"ppo": {"batch_size": 0}}, r"train_drl\.ppo\.batch_size: must be a whole number >= 1"),
        ({"ppo": {"gamma": 2.0}}, r"train_drl\.ppo\.gamma: must be a number in \[0, 1\]"),
        ({"eval_side_m": 52}, r"train_drl.eval_side_m: maze_side_m 52"),
        ({"device": "tpu"}, r"train_drl\.device: must be one of 'cpu', 'cuda', 'auto'"),
        ({"experiment": ""}, r"train_drl\.experiment: must be a non-empty string \(an MLflow experiment\)"),
        (
            {"timestep": 64},
            r"train_drl\.timestep: unknown setting \(known: model, env, ppo, imitation, init_checkpoint, timesteps, checkpoint_every, eval_mazes, eval_side_m, eval_seed, seed, threads, device, experiment\)",
        ),
        ({"seed": None}, r"train_drl\.seed: missing \(the params file names every setting\)"),
    ],
)
def test_the_stage_refuses_bad_settings(tmp_path, monkeypatch, change, message):
    monkeypatch.chdir(tmp_path)
    section = tiny_section()
    for key, value in change.items():
        if value is None:
            del section[key]  # a missing key
        elif isinstance(value, dict) and isinstance(section.get(key), dict):
            section[key] = {**section[key], **value}
        else:
            section[key] = value
    write_params(tmp_path, section)
    with pytest.raises(ValueError, match=message):
        train_drl.main("params.yaml")
    assert not (tmp_path / "models").exists() and not (tmp_path / "checkpoints").exists()


def test_a_bad_timesteps_argument_is_refused(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    write_params(tmp_path, tiny_section())
    with pytest.raises(ValueError, match=r"--timesteps: must be a whole number >= 1, got -5"):
        train_drl.main("params.yaml", timesteps=-5)


def test_a_bad_reward_weight_is_refused_like_the_other_settings(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    section = tiny_section()
    section["env"]["completion_bonus"] = -20.0
    write_params(tmp_path, section)
    with pytest.raises(ValueError, match=r"params.yaml: train_drl.env.*completion_bonus"):
        train_drl.read_params("params.yaml")


class Killed(Exception):
    """Stands for the run being killed right after a checkpoint was written."""


def test_a_checkpoint_holds_the_weights_trained_on_its_steps(project, monkeypatch):
    folder, _, _ = project
    section = {**tiny_section(), "eval_mazes": 0, "checkpoint_every": 64}
    write_params(folder, section)
    train_drl.main("params.yaml")  # 64 steps, one rollout and its update, uninterrupted
    trained, _ = load_drl_policy(folder / "models/drl/policy.pt")

    other = folder / "killed"
    other.mkdir()
    monkeypatch.chdir(other)
    write_params(other, section)
    save = train_drl_workflow.Checkpointer.save

    def save_then_die(self):
        save(self)
        if self.num_timesteps >= 64:
            raise Killed

    monkeypatch.setattr(train_drl_workflow.Checkpointer, "save", save_then_die)
    with pytest.raises(Killed):
        train_drl.main("params.yaml", timesteps=128)
    record = json.loads((other / "checkpoints/drl/last.json").read_text())
    assert record["timesteps"] == 64
    from sb3_contrib import MaskablePPO

    checkpoint = MaskablePPO.load(other / "checkpoints/drl/last.zip", device="cpu").policy.drl_policy
    for name, value in trained.state_dict().items():
        assert torch.equal(checkpoint.state_dict()[name], value), name
    assert [row["timesteps"] for row in record["history"]] == [64.0]
