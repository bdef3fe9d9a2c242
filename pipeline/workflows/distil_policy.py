"""DAgger (the `distil_policy` stage, ours): the guide policy distilled from a belief-only teacher,
with the policy driving.

The policy trained on the ground-truth expert (`train_planner`) imitates moves that depend on a map
the robot cannot see. Here its teacher sees only the belief (gated greedy,
`greedy_utility:sliver_gate=true`, by default: deterministic given the belief, its target a node
of the graph the policy sees) and labels each state with the first T_p steps of the shortest
known path toward its target (`pipeline.data.teacher_labels`).

- Round 0: the teacher drives `teacher_episodes` episodes on training mazes and labels its own
  states; the policy (from `start_policy`) is fine-tuned on them.
- Round r >= 1: the policy of round r - 1 drives `episodes` episodes as the paper's planner
  (`guide:mode=policy`), the teacher labels every state it reaches, the data of every round so far
  is aggregated and the policy fine-tuned on it (from round r - 1's weights).

After each round its policy drives `eval_mazes` fresh mazes (`eval_seed`, never the test mazes)
beside `greedy_utility`, paired; the start policy does too, as the line the rounds are measured
from. Every round's work is kept in checkpoints/distil/round_<r>/ (shards, observations, training
checkpoints, evaluation), so a killed run takes up where it was; the rounds' labelled episodes are
published under data/dagger/.
"""

from __future__ import annotations

import json
import math
import shutil
import time
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from pydantic import field_validator

from pipeline.common.atomic import atomic_file, atomic_folder, atomic_write_json
from pipeline.common.config import Section, every_key, flag, maybe, positive, text, whole
from pipeline.common.executor import run_tasks
from pipeline.common.fingerprints import files_digest, settings_digest, source_digest
from pipeline.common.kept_results import KeptResults
from pipeline.common.mlflow_store import import_mlflow, log_generated_maze_set, log_maze_set, resolve_tracking_uri
from pipeline.common.paths import CHECKPOINTS, DATA, MODELS, POLICIES, REPORTS
from pipeline.data.collect import COLLECTION_SOURCES
from pipeline.data.dagger import DaggerConfig, collect_dagger_shard
from pipeline.data.observations import concatenate, load_observations, save_observations, shard_observations
from pipeline.data.shards import read_manifest, run_shards, shard_count_for
from pipeline.evaluation.statistics import paired_difference
from pipeline.models.defaults import PIPELINE_INPAINTER, PIPELINE_POLICY
from pipeline.models.modeling_diffusion import load_policy
from pipeline.planners.registry import make_config
from pipeline.planners.specs import PlannerSpec
from pipeline.reporting.training_figures import dagger_rounds_figure
from pipeline.training.policy import PlannerTrainConfig, train_planner
from pipeline.training.policy_launch import train_in_subprocess
from pipeline.training.run_setup import DEVICES, resume_point, start_afresh
from pipeline.workflows.benchmark import benchmark_with_summary
from pipeline.workflows.stage_inputs import generated_maps
from pipeline.world.mazes import MazeConfig, generate_maze_set
from pipeline.world.protocol import Protocol

BASELINE = "greedy_utility"
STUDENT_LABEL = "guide_policy"  # the policy driving as the paper's planner: guide in mode policy
TEACHER_MODELS = (MODELS.inpainter, MODELS.block_model, MODELS.sliver_gate, POLICIES["guide"].model)


class Teacher(Section):
    """The planner DAgger imitates: a registered planner and options it accepts (it must report its
    target: the run says so when it does not)."""

    planner: Annotated[str, text(note="a registered planner name")]
    options: dict[str, Any] = {}

    @field_validator("options")
    @classmethod
    def _options_the_planner_takes(cls, options: dict[str, Any], info: Any) -> dict[str, Any]:
        if info.data.get("planner") is not None:
            make_config(info.data["planner"], **options)
        return options


class Settings(Section):
    """The `distil_policy` section of params.yaml."""

    teacher: Teacher
    start_policy: Annotated[str | None, maybe(text(note="a guide policy export"), "models/planner_guide/policy.pt")]
    inpainter: Annotated[str | None, maybe(text(note="an inpainter export"), "models/inpainter/inpainter.pt")]
    rounds: Annotated[int, whole(0, note="DAgger rounds after round 0")]
    teacher_episodes: Annotated[int, whole(1)]
    episodes: Annotated[int, whole(1)]
    episodes_per_shard: Annotated[int, whole(1)]
    random_starts: Annotated[bool, flag()]
    seed: Annotated[int, whole(0)]
    train: Annotated[PlannerTrainConfig, every_key(PlannerTrainConfig)]
    eval_mazes: Annotated[int, whole(2, note="paired comparison needs at least 2")]
    eval_side_m: Annotated[float, positive("metres")]
    eval_seed: Annotated[int, whole(0)]
    workers: Annotated[int, whole(0, note="0 or 1: in this process")]
    threads: Annotated[int | None, maybe(whole(0, note="0: torch's default"), "torch's default")]
    accelerator: Annotated[str, text(note="Lightning's accelerator: cpu, gpu, auto")]
    devices: Annotated[int | list[int] | str, DEVICES] = 1
    experiment: Annotated[str, text(note="an MLflow experiment")]


def round_folder(r: int) -> Path:
    return CHECKPOINTS.distil / f"round_{r}"


def start_policy_path(settings: Settings) -> Path:
    path = Path(settings.start_policy or PIPELINE_POLICY["guide"])
    if not path.is_file():
        raise SystemExit(f"error: {path}: no start policy; run the train_planner@guide stage first")
    return path


def observation_settings(start_meta: dict) -> dict:
    """The graph observations the start policy was trained on (its export says): the rounds' data
    is built the same way, so that the fine-tuned policy sees the graphs the planner builds."""
    seen = dict(start_meta.get("observations") or {})
    if seen.get("variant", "guide") != "guide":
        raise SystemExit(
            f"error: the start policy was trained on {seen['variant']} observations; distil_policy "
            "fine-tunes a guide policy"
        )
    return {
        "threshold": float(seen.get("threshold", 0.8)),
        "count_threshold": float(seen.get("count_threshold", 0.5)),
        "min_component": int(seen.get("min_component", 3)),
        "max_nodes": int(seen.get("max_nodes", 128)),
        "max_neighbors": int(seen.get("max_neighbors", 25)),
    }


# ----------------------------------------------------------------------------- one round's data
def collect_round(settings: Settings, protocol: Protocol, r: int, student: Path | None, horizon: int) -> dict:
    """Round r's labelled episodes: made in checkpoints/, published at data/dagger/round_<r>; its manifest."""
    episodes = settings.teacher_episodes if student is None else settings.episodes
    per_shard = settings.episodes_per_shard
    config = DaggerConfig(
        maps=tuple(str(p) for p in generated_maps(DATA.mazes_train, "training mazes")),
        episodes_per_shard=per_shard,
        teacher=settings.teacher.planner,
        teacher_options=dict(settings.teacher.options),
        student=None if student is None else str(student),
        horizon=horizon,
        seed=settings.seed,
        round=r,
        protocol=protocol,
        random_starts=settings.random_starts,
    )
    # The labels depend on the teacher's models and the driver's weights, not only on their paths.
    models = {
        "teacher": files_digest([p for p in TEACHER_MODELS if p.exists()]),
        "student": None if student is None else files_digest([student]),
    }
    who = "the teacher drives" if student is None else "the policy drives"
    return run_shards(
        collect_dagger_shard,
        shard_count_for(episodes, per_shard, "episodes"),
        DATA.dagger / f"round_{r}",
        {"config": config},
        workers=settings.workers,
        description=f"round {r} ({who})",
        sources=COLLECTION_SOURCES,
        work_dir=round_folder(r) / "shards",
        inputs=models,
    )


def _shard_observations(task: tuple) -> dict:
    """Guide observations of every episode of one round shard (runs in a worker process)."""
    shard, first_episode_id, protocol_dict, inpainter, settings = task
    return shard_observations(
        shard, first_episode_id, Protocol.from_dict(protocol_dict), inpainter, settings, variants=("guide",)
    )["guide"]


def round_observations(
    protocol: Protocol, r: int, first_episode: int, settings: dict, inpainter: Path, workers: int
) -> dict[str, np.ndarray]:
    """Round r's episodes replayed into guide observations (episode ids from `first_episode`)."""
    folder = DATA.dagger / f"round_{r}"
    entries = read_manifest(folder)["shards"]
    counts = [int(entry["episodes"]) for entry in entries]
    firsts = first_episode + np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(int)
    tasks = [
        (str(folder / entry["file"]), int(f), protocol.to_dict(), str(inpainter), settings)
        for entry, f in zip(entries, firsts)
    ]
    identity = {
        "tasks": tasks,
        "data": files_digest([folder]),
        "inpainter": files_digest([inpainter]),
        "source": source_digest(),
    }
    results = run_tasks(
        _shard_observations,
        tasks,
        workers,
        f"round {r} observations",
        "shard",
        keep=KeptResults(round_folder(r) / "observations", identity),
    )
    return concatenate(results)


# ----------------------------------------------------------------------------- one round's policy
def train_round(settings: Settings, r: int, aggregate: Path, init: Path, model: dict) -> tuple[Path, dict]:
    """Fine-tune from `init` on the aggregate; the export and its metadata. A killed training
    resumes from its checkpoint when its settings, data and starting weights are the same.

    On one device the training runs in this process. On several (`devices`, DDP), it runs in a
    child process that only trains (`train_in_subprocess`), because DDP starts its other processes
    by running the script again, and a rerun of this stage would collect the round again."""
    train = dict(settings.as_written()["train"])  # as the file names it: the fingerprint and the export record it
    folder = round_folder(r)
    devices = settings.devices
    layout = {"accelerator": settings.accelerator, **({"devices": devices} if devices != 1 else {})}
    fingerprint = settings_digest(
        {"model": model, "train": train, **layout, "data": files_digest([aggregate]), "init": files_digest([init])}
    )
    checkpoints = folder / "training"
    resume_from = resume_point(checkpoints, fingerprint, f"distil_policy round {r}")
    if resume_from is None:
        start_afresh(checkpoints, fingerprint)
    arguments: dict[str, Any] = dict(
        observations=aggregate,
        out_dir=folder / "policy",
        model_config=model,
        train_config=train,
        accelerator=settings.accelerator,
        devices=devices,
        resume=resume_from is not None,
        checkpoint_dir=checkpoints,
        experiment_name=settings.experiment,
        run_name=f"distil round {r}",
        num_threads=settings.threads,
        init_policy=init,
    )
    export = train_planner(**arguments) if devices == 1 else train_in_subprocess(**arguments)
    assert export is not None  # one device: this process exports; several: the child's rank zero did
    _, meta = load_policy(export)
    return export, meta


# ----------------------------------------------------------------------------- closed loop
def eval_mazes(settings: Settings, protocol: Protocol) -> list[Path]:
    """The fresh evaluation mazes (seed `eval_seed`), drawn once into checkpoints/distil/eval_mazes."""
    count, side = settings.eval_mazes, settings.eval_side_m
    folder = CHECKPOINTS.distil / f"eval_mazes_{count}_{side:g}m_seed{settings.eval_seed}"
    paths = sorted(folder.glob("maze_*.png"))
    if len(paths) != count:  # none yet, or another count: drawn afresh (the folder replaced whole)
        config = MazeConfig(side_m=(side, side), cell_size=protocol.cell_size)
        with atomic_folder(folder) as tmp:
            generate_maze_set(config, count, tmp, seed=settings.eval_seed, progress=False)
        paths = sorted(folder.glob("maze_*.png"))
    return paths


def closed_loop(settings: Settings, protocol: Protocol, policy: Path, name: str, mazes: list[Path]) -> dict:
    """`guide:mode=policy` with `policy` and `greedy_utility` on the evaluation mazes, paired; kept
    in checkpoints/distil/ under `name` (a rerun with the same policy and mazes reads it back)."""
    folder = CHECKPOINTS.distil / f"eval_{name}"
    identity = settings_digest(
        {
            "policy": files_digest([policy]),
            "mazes": files_digest(mazes),
            "protocol": protocol.to_dict(),
            "source": source_digest(),
        }
    )
    record = folder / "closed_loop.json"
    if record.is_file():
        kept = json.loads(record.read_text())
        if kept.get("identity") == identity:
            return kept["result"]
    shutil.rmtree(folder, ignore_errors=True)
    specs = [BASELINE, PlannerSpec(STUDENT_LABEL, "guide", {"mode": "policy", "policy_file": str(policy)})]
    frame = benchmark_with_summary(mazes, specs, protocol, folder, workers=settings.workers, progress=True).frame
    mean, half, maps = paired_difference(frame, STUDENT_LABEL, BASELINE)
    ours = frame[frame.planner == STUDENT_LABEL]
    result = {
        "mazes": maps,
        "distance_m": round(float(ours.distance_m.mean()), 1),
        "greedy_utility_distance_m": round(float(frame[frame.planner == BASELINE].distance_m.mean()), 1),
        "vs_greedy_pct": round(100 * mean, 2),
        "vs_greedy_ci95_pct": None if math.isnan(half) else round(100 * half, 2),
        "completed": int(ours.complete.sum()),
        "decision_ms_median": round(float(ours.decision_ms_median.median()), 1)
        if "decision_ms_median" in ours
        else None,
    }
    atomic_write_json(record, {"identity": identity, "result": result})
    return result


# ----------------------------------------------------------------------------- the rounds
def distil_policy(settings: Settings, protocol: Protocol) -> dict:
    """Round 0 and `rounds` DAgger rounds from the `distil_policy` settings; the summary."""
    started = time.perf_counter()
    start = start_policy_path(settings)
    _, start_meta = load_policy(start)
    observed = observation_settings(start_meta)
    model = dict(start_meta["config"])
    horizon = int(model["horizon"])
    inpainter = Path(settings.inpainter or PIPELINE_INPAINTER)
    if not inpainter.is_file():
        raise SystemExit(f"error: {inpainter}: no inpainter export; run the train_inpainter stage first")
    workers = max(1, settings.workers)
    mazes = eval_mazes(settings, protocol)
    rows: list[dict[str, Any]] = [
        {"round": "start", "policy": str(start), **closed_loop(settings, protocol, start, "start", mazes)}
    ]
    parts: list[dict[str, np.ndarray]] = []
    policy, episodes_so_far = start, 0
    teacher = settings.as_written()["teacher"]  # as the file names it: the data and the summary record it
    meta_for_file = {"variant": "guide", **observed, "protocol": protocol.to_dict(), "teacher": teacher}
    for r in range(settings.rounds + 1):
        manifest = collect_round(settings, protocol, r, None if r == 0 else policy, horizon)
        totals = manifest["totals"]
        parts.append(round_observations(protocol, r, episodes_so_far, observed, inpainter, workers))
        episodes_so_far += int(totals["episodes"])
        aggregate = round_folder(r) / "aggregate.npz"
        arrays = concatenate(parts)
        if not aggregate.is_file() or not _same_arrays(aggregate, arrays):
            save_observations(aggregate, arrays, {**meta_for_file, "rounds": r + 1})
        policy, meta = train_round(settings, r, aggregate, policy, model)
        last = (meta.get("history") or [{}])[-1]
        row = {
            "round": r,
            "driver": "teacher" if r == 0 else f"policy of round {r - 1}",
            "episodes": int(totals["episodes"]),
            "complete": int(totals["complete"]),
            "labelled_steps": int(totals["steps"]),
            "aggregate_steps": int(len(arrays["episode"])),
            # The driver's moves that were the teacher's first step (round 0: the teacher's own chunked moves).
            "driver_agreement": round(totals["agreements"] / max(1, totals["moves"]), 4),
            "heldout_agreement": last.get("val_first_step_accuracy"),
            "train_seconds": meta.get("train_seconds"),
            "policy": str(policy),
            **closed_loop(settings, protocol, policy, f"round_{r}", mazes),
        }
        rows.append(row)
        print(
            f"round {r}: {row['labelled_steps']} labelled steps ({row['driver']}), driver agreement "
            f"{row['driver_agreement']:.0%}, held-out agreement {row['heldout_agreement']:.0%}; guide:mode=policy "
            f"{row['distance_m']} m against greedy_utility {row['greedy_utility_distance_m']} m "
            f"({row['vs_greedy_pct']:+.1f} %) on {row['mazes']} fresh mazes"
        )
    MODELS.planner_distilled.mkdir(parents=True, exist_ok=True)
    with atomic_file(MODELS.planner_distilled / "policy.pt") as tmp:
        shutil.copyfile(policy, tmp)
    summary = {
        "teacher": teacher,
        "start_policy": str(start),
        "eval": {"mazes": len(mazes), "side_m": settings.eval_side_m, "seed": settings.eval_seed},
        "rounds": rows,
        "seconds": round(time.perf_counter() - started, 1),
    }
    atomic_write_json(REPORTS.distil, summary)
    dagger_rounds_figure(rows, REPORTS.distil_figure)
    log_rounds(settings, rows)
    return summary


def _same_arrays(path: Path, arrays: dict[str, np.ndarray]) -> bool:
    kept, _ = load_observations(path)
    return all(np.array_equal(kept[k], arrays[k]) for k in arrays)


def log_rounds(settings: Settings, rows: list[dict]) -> None:
    """One MLflow run with each round's figures as a step (the MLflow curves of the rounds)."""
    mlflow = import_mlflow()
    mlflow.set_tracking_uri(resolve_tracking_uri(None))
    mlflow.set_experiment(settings.experiment)
    s, teacher = settings, settings.teacher
    with mlflow.start_run(run_name="distil rounds"):
        log_maze_set(DATA.mazes_train, "training")
        log_generated_maze_set(
            f"evaluation mazes ({s.eval_mazes} of {s.eval_side_m:g} m)",
            {"generator": "guide mazes", "count": s.eval_mazes, "side_m": s.as_written()["eval_side_m"]}
            | {"seed": s.eval_seed},  # the side as the file names it: the set's digest
            "evaluation",
        )
        mlflow.log_params(
            {"teacher": teacher.planner, **{f"teacher.{k}": v for k, v in teacher.options.items()}}
            | {"rounds": s.rounds, "episodes": s.episodes, "teacher_episodes": s.teacher_episodes}
            | {"eval_mazes": s.eval_mazes}
        )
        for step, row in enumerate(rows):
            metrics = {
                k: row[k]
                for k in ("distance_m", "vs_greedy_pct", "heldout_agreement", "driver_agreement", "aggregate_steps")
                if isinstance(row.get(k), (int, float))
            }
            mlflow.log_metrics(metrics, step=step)
