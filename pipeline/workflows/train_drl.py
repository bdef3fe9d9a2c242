"""The `train_drl` stage's job: train the `drl` policy by MaskablePPO in `guide/Explore-v0`,
export it, and measure it against `nearest_frontier` on fresh mazes.

Checkpoints (`checkpoints/drl/last.zip`, with `last.json`: the settings' fingerprint, the steps
done and the curve so far) are written every `checkpoint_every` steps, outside the stage's
outputs, which DVC deletes before it reruns a stage. A run finds them and continues when they
were made with the same settings and protocol, and starts afresh, saying so, when not. A
resumed run reseeds its environments (their random state is not in the checkpoint), so its
mazes differ from an uninterrupted run's after the resume.

Writes models/drl/policy.pt (the export the planner loads), reports/drl_metrics.json (the
curve, the evaluation and the times) and reports/drl_curves.png, and logs one MLflow run in
the section's experiment (per-rollout curves: episode return, distance, explored share).
"""

from __future__ import annotations

import hashlib
import json
import os
import time
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, cast

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback, CallbackList
from tqdm.auto import tqdm

from pipeline.common.config import Section, every_key, maybe, positive, text, whole
from pipeline.common.mlflow_store import import_mlflow, log_generated_maze_set, resolve_tracking_uri
from pipeline.common.paths import CHECKPOINTS, REPORTS
from pipeline.models.configuration_drl import DRLPolicyConfig
from pipeline.models.defaults import PIPELINE_DRL
from pipeline.models.modeling_drl import load_drl_policy, save_drl_policy
from pipeline.planners import make_planner
from pipeline.planners.wrapper import innermost
from pipeline.reporting.training_figures import drl_training_curves
from pipeline.training.drl import (
    EpisodeLog,
    PPOSettings,
    TrainingEnvironment,
    load_agent,
    new_agent,
    policy_of,
    vector_env,
    write_json,
)
from pipeline.training.drl_imitation import ImitationSettings, warm_start
from pipeline.training.run_setup import torch_threads, training_host
from pipeline.world.protocol import Protocol
from pipeline.world.simulator import run_episode

if TYPE_CHECKING:
    from pipeline.planners.baselines.drl import DRLPlanner

MODEL_PATH = PIPELINE_DRL
CHECKPOINT_DIR = CHECKPOINTS.drl
METRICS_PATH = REPORTS.drl
FIGURE_PATH = REPORTS.drl_curves


class Settings(Section):
    """The `train_drl` section of params.yaml."""

    model: DRLPolicyConfig
    env: Annotated[TrainingEnvironment, every_key(TrainingEnvironment)]
    ppo: Annotated[PPOSettings, every_key(PPOSettings)]
    imitation: Annotated[ImitationSettings, every_key(ImitationSettings)]
    init_checkpoint: Annotated[str | None, maybe(text(note="a drl export"), "the warm start")]
    timesteps: Annotated[int, whole(1)]
    checkpoint_every: Annotated[int, whole(1)]
    eval_mazes: Annotated[int, whole(0)]
    eval_side_m: Annotated[float, positive("metres")]
    eval_seed: Annotated[int, whole(0)]
    seed: Annotated[int, whole(0)]
    threads: Annotated[int, whole(0, note="0: torch's default")]
    device: Annotated[str, text(("cpu", "cuda", "auto"))]
    experiment: Annotated[str, text(note="an MLflow experiment")]


# What a checkpoint must share to be continued: not `timesteps`, so a run can be trained on for
# longer (the learning rate is constant, so a continued run is a longer one).
TRAINING_KEYS = ("model", "env", "ppo", "imitation", "init_checkpoint", "seed")


def settings_fingerprint(settings: Settings, protocol: Protocol) -> str:
    """A hash of everything the trained weights depend on (the training keys, as the file names
    them, and the protocol)."""
    payload = json.dumps(
        {"train_drl": settings.as_written(*TRAINING_KEYS), "protocol": protocol.to_dict()}, sort_keys=True, default=str
    )
    return hashlib.sha256(payload.encode()).hexdigest()[:16]


class Checkpointer(BaseCallback):
    """Saves the agent and its curve every `every` steps (and at the end), atomically: at the start
    of a rollout, so that a checkpoint holds the weights PPO trained on every step it counts."""

    def __init__(
        self,
        every: int,
        fingerprint: str,
        log: EpisodeLog,
        folder: Path = CHECKPOINT_DIR,
        extra: dict[str, Any] | None = None,
    ):
        super().__init__()
        self.every, self.fingerprint, self.log, self.folder = every, fingerprint, log, folder
        self.extra = extra or {}
        self._last = 0

    def _on_step(self) -> bool:
        return True

    def _on_rollout_start(self) -> None:
        if self.num_timesteps - self._last >= self.every:
            self.save()

    def save(self) -> None:
        self._last = self.num_timesteps
        self.folder.mkdir(parents=True, exist_ok=True)
        zip_tmp = self.folder / f".last.{os.getpid()}.zip"
        self.model.save(zip_tmp)
        os.replace(zip_tmp, self.folder / "last.zip")
        json_tmp = self.folder / f".last.{os.getpid()}.json"
        json_tmp.write_text(
            json.dumps(
                {
                    "fingerprint": self.fingerprint,
                    "timesteps": self.num_timesteps,
                    "history": self.log.rows,
                    **self.extra,
                }
            )
            + "\n"
        )
        os.replace(json_tmp, self.folder / "last.json")


class ProgressBar(BaseCallback):
    """A progress bar over the whole run's steps (a resumed run starts it where the checkpoint was)."""

    def __init__(self, total: int, done: int):
        super().__init__()
        self.bar = tqdm(total=total, initial=done, desc="train_drl", unit="step", mininterval=2.0)

    def _on_step(self) -> bool:
        self.bar.update(min(self.num_timesteps, self.bar.total) - self.bar.n)  # tqdm redraws at most every 2 s
        return True

    def _on_training_end(self) -> None:
        self.bar.close()


def previous_checkpoint(fingerprint: str, total: int, folder: Path = CHECKPOINT_DIR) -> dict[str, Any] | None:
    """The checkpoint's record when one made with these settings, at most `total` steps in, is
    there; else None (saying why when there is one)."""
    record_path, agent_path = folder / "last.json", folder / "last.zip"
    if not record_path.is_file() or not agent_path.is_file():
        return None
    try:
        record = json.loads(record_path.read_text())
    except (OSError, ValueError):
        print(f"train_drl: {record_path} is unreadable; training afresh", flush=True)
        return None
    if record.get("fingerprint") != fingerprint:
        print(f"train_drl: the checkpoint in {folder} was made with other settings; training afresh", flush=True)
        return None
    if int(record.get("timesteps", 0)) > total:
        print(
            f"train_drl: the checkpoint in {folder} is {record['timesteps']} steps in, past the {total} asked for; "
            "training afresh",
            flush=True,
        )
        return None
    return record


def train_the_drl_policy(settings: Settings, protocol: Protocol) -> dict[str, Any]:
    """Train (or continue), export, evaluate and report the drl policy from the `train_drl` settings."""
    policy_config, environment, ppo = settings.model, settings.env, settings.ppo
    total, seed = settings.timesteps, settings.seed
    fingerprint = settings_fingerprint(settings, protocol)
    started = time.perf_counter()
    with torch_threads(settings.threads):
        record = previous_checkpoint(fingerprint, total)
        done = int(record["timesteps"]) if record else 0
        envs = vector_env(environment, protocol, policy_config, ppo, seed + done)
        if record:
            print(f"train_drl: continuing from the checkpoint at {done} of {total} steps", flush=True)
            agent = load_agent(CHECKPOINT_DIR / "last.zip", envs, settings.device)
            warm = record.get("warm_start")  # what the killed run started from
        else:
            agent = new_agent(envs, policy_config, ppo, seed, settings.device)
            warm = start_policy(policy_of(agent), settings, protocol, ppo.gamma)
        log = EpisodeLog(_print_row)
        log.rows = list(record["history"]) if record else []
        checkpointer = Checkpointer(settings.checkpoint_every, fingerprint, log, extra={"warm_start": warm})
        if total > done:
            agent.learn(
                total - done,
                callback=CallbackList([log, checkpointer, ProgressBar(total, done)]),
                reset_num_timesteps=not record,
            )
            checkpointer.save()
        envs.close()
        train_seconds = time.perf_counter() - started
        policy = policy_of(agent).cpu().eval()
        host = training_host(settings.device)
        trained_on = {
            "protocol": protocol.to_dict(),
            "env": environment.to_dict(),
            "ppo": ppo.to_dict(),
            "timesteps": int(agent.num_timesteps),
            "seed": seed,
            "host": host,
        }
        save_drl_policy(policy, MODEL_PATH, trained_on)
        evaluation = evaluate_on_fresh_mazes(
            policy,
            environment,
            policy_config,
            protocol,
            settings.eval_mazes,
            settings.as_written()["eval_side_m"],  # as the file names it: the metrics record it
            settings.eval_seed,
        )
    metrics = {
        "timesteps": int(agent.num_timesteps),
        "resumed_from": done,
        "warm_start": warm,
        "train_seconds": round(train_seconds, 1),
        "parameters": sum(p.numel() for p in policy.parameters()),
        "evaluation": evaluation,
        "history": [{k: round(v, 4) for k, v in row.items()} for row in log.rows],
        "host": host,
    }
    write_json(METRICS_PATH, metrics)
    drl_training_curves(log.rows, evaluation, FIGURE_PATH)
    log_run(settings, protocol, metrics)
    return metrics


def start_policy(policy, settings: Settings, protocol: Protocol, gamma: float) -> dict[str, Any] | None:
    """Set the fresh agent's policy before PPO: the weights of `init_checkpoint`, else the imitation
    warm start when it has episodes, else nothing (PPO from the initial weights). What it did."""
    init, policy_config = settings.init_checkpoint, settings.model
    if init:
        initial, trained_on = load_drl_policy(init)
        if initial.config != policy_config:
            raise ValueError(
                f"train_drl.init_checkpoint {init}: its model {initial.config.to_dict()} "
                f"differs from train_drl.model {policy_config.to_dict()}"
            )
        policy.load_state_dict(initial.state_dict())
        return {"init_checkpoint": str(init), "its_training": trained_on.get("warm_start")}
    imitation = settings.imitation
    if imitation.episodes == 0:
        return None
    make = lambda i: settings.env.make(i, protocol, policy_config)  # noqa: E731
    result = warm_start(policy, make, imitation, gamma, settings.seed + 10_000)
    policy.train()
    for phase in result["phases"]:
        last = phase["epochs"][-1]
        tqdm.write(
            f"train_drl: {phase['phase']}: {phase['distance_m']:.0f} m, completed {phase['completed']:.0%}, "
            f"agreement with {imitation.planner} {last['agreement']:.1%}"
        )
    return result


def _print_row(row: dict[str, float]) -> None:
    keys = ("timesteps", "episodes", "episode_return", "episode_distance_m", "explored_share", "completed_share")
    tqdm.write(json.dumps({k: round(row[k], 3) for k in keys if k in row}))


def evaluate_on_fresh_mazes(
    policy,
    environment: TrainingEnvironment,
    policy_config: DRLPolicyConfig,
    protocol: Protocol,
    count: int,
    side_m: float,
    seed: int,
) -> dict[str, Any]:
    """The `drl` planner with this policy (its default stall hand-over included) on `count` fresh
    mazes of `side_m` metres, drawn by the environment from seeds seed, seed + 1, ..., beside
    `nearest_frontier` on the same mazes; the paired difference is drl's distance over the
    baseline's, minus one."""
    if count == 0:
        return {}
    sides = TrainingEnvironment(maze_sides_m=[side_m], max_steps=protocol.max_steps)
    env = sides.make(0, protocol, policy_config)
    rows = []
    for i in tqdm(range(count), desc="train_drl evaluation", unit="maze", mininterval=2.0):
        env.reset(seed=seed + i)
        planner = make_planner("drl", policy=policy)
        result = run_episode(env.ground_truth, planner, protocol)
        baseline = run_episode(env.ground_truth, make_planner("nearest_frontier"), protocol)
        rows.append(
            {
                "map": env.ground_truth.name,
                "distance": result.distance_m,
                "complete": result.complete,
                "steps": result.steps,
                "handovers": cast("DRLPlanner", innermost(planner)).handovers,
                "nearest_frontier_distance": baseline.distance_m,
                "nearest_frontier_complete": baseline.complete,
            }
        )
    env.close()
    drl, nf = np.array([r["distance"] for r in rows]), np.array([r["nearest_frontier_distance"] for r in rows])
    return {
        "mazes": count,
        "side_m": side_m,
        "seed": seed,
        "completed": int(sum(r["complete"] for r in rows)),
        "distance_m": round(float(drl.mean()), 1),
        "nearest_frontier_distance_m": round(float(nf.mean()), 1),
        "paired_vs_nearest_frontier": round(float(np.mean(drl / nf - 1.0)), 4),
        "episodes": [{k: (round(v, 2) if isinstance(v, float) else v) for k, v in r.items()} for r in rows],
    }


def log_run(settings: Settings, protocol: Protocol, metrics: dict[str, Any]) -> None:
    mlflow = import_mlflow()
    mlflow.set_tracking_uri(resolve_tracking_uri(None))
    mlflow.set_experiment(settings.experiment)
    section = settings.as_written()  # the params as the file names them
    flat = {f"{group}.{k}": v for group in ("model", "env", "ppo") for k, v in section[group].items()}
    with mlflow.start_run(run_name="train_drl"):
        log_generated_maze_set(
            "training environments' mazes (a fresh one at every reset)",
            {"generator": "guide/Explore-v0", "maze_sides_m": section["env"]["maze_sides_m"], "seed": settings.seed},
        )
        log_generated_maze_set(
            f"evaluation mazes ({settings.eval_mazes} of {settings.eval_side_m:g} m)",
            {"generator": "guide/Explore-v0", "count": settings.eval_mazes, "side_m": section["eval_side_m"]}
            | {"seed": settings.eval_seed},
            "evaluation",
        )
        mlflow.log_params(
            {**protocol.to_dict(), **flat, **{k: v for k, v in section.items() if k not in ("model", "env", "ppo")}}
        )
        for row in metrics["history"]:
            mlflow.log_metrics({k: v for k, v in row.items() if k != "timesteps"}, step=int(row["timesteps"]))
        evaluation = metrics["evaluation"]
        summary = {"train_seconds": metrics["train_seconds"], "timesteps": metrics["timesteps"]}
        if evaluation:
            summary.update(
                eval_distance_m=evaluation["distance_m"],
                eval_completed=evaluation["completed"],
                eval_nearest_frontier_distance_m=evaluation["nearest_frontier_distance_m"],
                eval_paired_vs_nearest_frontier=evaluation["paired_vs_nearest_frontier"],
            )
        mlflow.log_metrics({k: float(v) for k, v in summary.items()})
        for key, value in metrics["host"].items():
            mlflow.set_tag(f"trained_on.{key}", value)
        for path in (MODEL_PATH, METRICS_PATH, FIGURE_PATH):
            if path.is_file():
                mlflow.log_artifact(str(path))
