"""What the paper profile (`profiles/paper.yaml`) costs, from unit costs measured on this machine.

Usage: python benchmarks/cost_paper_profile.py [--profile profiles/paper.yaml] [--mazes 2]
                                               [--skip-benchmark-planners optimal,sampled_lookahead]
                                               [--save-units FILE | --units FILE]

Measures, one core each (torch on this machine's threads for the training steps):
  - one Stage I pair (`collect_pairs_shard`, the profile's planners, on paper-size training mazes),
  - one expert episode (`collect_expert_shard`) and its graph observations (`shard_observations`),
  - one training step of the inpainter and of the policy at the profile's batch and model,
  - one DAgger episode (the profile's teacher driving a 100 m maze),
  - one benchmark episode of each of the profile's planners on a 100 m maze,
then multiplies by the profile's counts and prints each stage's wall time on: this machine,
one 64-core machine with 8 GPUs, and a Ray cluster of 10 x 16 cores plus one GPU node.

The model, stated so that its figures can be checked: episode and shard workloads scale with the
cores they are spread over (the executor's engines; Ray's overhead ignored); a training takes
its CPU step cost on a machine without a GPU, and on G GPUs the step cost measured on an H200
(the inpainter 107 s for one epoch of 230,000
pairs at batch 64, the paper-size policy 4 epochs of 72,912 steps in 5 minutes at batch 256)
divided by G (DDP); stages run one after another, as `dvc repro` runs them. The block model and
the DRL baseline train on the CPU in every setting; their rates come from this project's
`reports/block_model.json` and `reports/drl_metrics.json` when a default run left them.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np
import torch
import yaml

from pipeline.data.collect import ExpertConfig, PairsConfig, collect_expert_shard, collect_pairs_shard
from pipeline.data.observations import PlannerDataset, crop_observations, shard_observations
from pipeline.data.shards import ShardJob, read_shard, shard_path
from pipeline.models import InpainterConfig, InpainterModel
from pipeline.models.configuration_diffusion import DiffusionPolicyConfig
from pipeline.models.modeling_diffusion import DiffusionPolicy
from pipeline.planners import make_planner
from pipeline.planners.specs import parse_planner_spec
from pipeline.training.inpainter_losses import inpainting_loss
from pipeline.training.policy import collate
from pipeline.world.maps import load_map
from pipeline.world.mazes import MazeConfig, generate_maze, write_maze_png
from pipeline.world.protocol import Protocol
from pipeline.world.simulator import run_episode

SHIPPED_INPAINTER = Path("pipeline/assets/inpainter.pt")
H200_INPAINTER_S_PER_PAIR = 107.0 / 230_000  # one epoch, batch 64
H200_POLICY_S_PER_SAMPLE = 300.0 / (4 * 72_912)  # paper-size policy, batch 256
SETTINGS = {  # name: (CPU nodes x cores, GPUs)
    "this machine": (1, os.cpu_count() or 1, 0),
    "one machine, 64 cores, 8 GPUs": (1, 64, 8),
    "Ray: 10 x 16 cores + a GPU node (16 cores, 1 GPU)": (11, 16, 1),
}


def timed(function, *args, **kwargs) -> tuple[float, object]:
    started = time.perf_counter()
    result = function(*args, **kwargs)
    return time.perf_counter() - started, result


def draw_mazes(folder: Path, count: int, side: tuple[float, float], seed: int) -> list[str]:
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for i in range(count):
        path = folder / f"maze_{i:04d}.png"
        write_maze_png(generate_maze(MazeConfig(side_m=side), np.random.default_rng([seed, i])), path)
        paths.append(str(path))
    return paths


def inpainter_step_seconds(model: dict, batch: int, size: int = 48, steps: int = 3) -> float:
    """One optimisation step of the generator on a batch of node images (the loss the stage uses)."""
    generator = InpainterModel(InpainterConfig.from_dict(model))
    optimiser = torch.optim.Adam(generator.parameters(), lr=1e-3)
    rng = np.random.default_rng(0)
    observed = torch.from_numpy(rng.choice([0, 128, 255], size=(batch, 1, size, size)).astype(np.uint8))
    target = torch.from_numpy(rng.choice([0, 255], size=(batch, 1, size, size)).astype(np.uint8))
    valid = torch.ones_like(observed)
    times = []
    for _ in range(steps + 1):
        started = time.perf_counter()
        logits = generator.forward_encoded_logits(generator.encode(observed))
        loss, _ = inpainting_loss(logits, observed, target, valid, 0.1, 1.0)
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
        times.append(time.perf_counter() - started)
    return float(np.median(times[1:]))


def policy_step_seconds(model: dict, batch: int, observations: dict, steps: int = 2) -> float:
    """One optimisation step of the policy's DDPM loss on a batch of real graph observations."""
    config = DiffusionPolicyConfig.from_dict(model)
    policy = DiffusionPolicy(config)
    optimiser = torch.optim.AdamW(policy.parameters(), lr=1e-4)
    arrays = crop_observations(observations, config.max_nodes)
    data = PlannerDataset(arrays, config.obs_steps)
    rows = [data[i % len(data)] for i in range(batch)]
    samples = collate(rows)
    times = []
    for _ in range(steps + 1):
        started = time.perf_counter()
        loss = policy.compute_loss(samples)
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
        times.append(time.perf_counter() - started)
    return float(np.median(times[1:]))


def episode_seconds(spec: str, maze: str, protocol: Protocol) -> tuple[float, int]:
    parsed = parse_planner_spec(spec)
    planner = make_planner(parsed.name, **parsed.options)
    seconds, result = timed(run_episode, load_map(maze, cell_size=protocol.cell_size), planner, protocol, 0)
    return seconds, int(result.steps)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--profile", default="profiles/paper.yaml")
    parser.add_argument("--mazes", type=int, default=2, help="mazes each unit is measured on")
    parser.add_argument(
        "--skip-benchmark-planners",
        default="",
        help="comma-separated planners of the benchmark list to leave out of the measurement "
        "(their episodes are then costed as the mean of the others)",
    )
    parser.add_argument("--save-units", help="write the measured unit costs to this JSON file")
    parser.add_argument("--units", help="cost from unit costs saved earlier (--save-units) instead of measuring")
    args = parser.parse_args()
    profile = yaml.safe_load(Path(args.profile).read_text())
    if args.units:
        print_costs(profile, json.loads(Path(args.units).read_text()))
        return
    protocol = Protocol.from_dict(profile["protocol"])
    torch.set_num_threads(max(1, min(4, os.cpu_count() or 1)))
    unit: dict[str, float] = {}
    with tempfile.TemporaryDirectory() as scratch:
        scratch = Path(scratch)
        train = draw_mazes(scratch / "train", args.mazes, tuple(profile["mazes"]["train"]["side_m"]), 31)
        test = draw_mazes(scratch / "test", args.mazes, tuple(profile["mazes"]["test"]["side_m"]), 32)

        pairs = profile["collect_pairs"]
        config = PairsConfig(
            maps=tuple(train),
            pairs_per_shard=40,
            planners=tuple(pairs["planners"]),
            snapshot_every=pairs["snapshot_every"],
            stop_steps=tuple(pairs["stop_steps"]),
            protocol=protocol,
        )
        seconds, _ = timed(collect_pairs_shard, ShardJob(0, str(scratch), "", {"config": config}))
        unit["pair"] = seconds / 40
        print(f"one Stage I pair: {unit['pair'] * 1e3:.0f} ms")

        expert = profile["collect_expert"]
        econfig = ExpertConfig(
            maps=tuple(train),
            episodes_per_shard=1,
            planner=expert["planner"],
            horizon=expert["horizon"],
            protocol=protocol,
            random_starts=bool(expert["random_starts"]),
        )
        seconds, _ = timed(collect_expert_shard, ShardJob(1, str(scratch), "", {"config": econfig}))
        steps = int(read_shard(shard_path(scratch, 1))["summary_steps"])
        unit["expert_episode"], unit["expert_steps"] = seconds, steps
        print(f"one expert episode: {seconds:.1f} s, {steps} steps")

        obs = profile["build_observations"]
        settings = {k: obs[k] for k in ("threshold", "count_threshold", "min_component", "max_nodes", "max_neighbors")}
        inpainter = obs.get("inpainter") or str(SHIPPED_INPAINTER)
        seconds, built = timed(shard_observations, shard_path(scratch, 1), 0, protocol, inpainter, settings)
        unit["observations_episode"] = seconds
        print(f"its graph observations: {seconds:.1f} s")

        tp, ti = profile["train_planner"], profile["train_inpainter"]
        unit["inpainter_step_cpu"] = inpainter_step_seconds(ti["model"], int(ti["batch_size"]))
        print(f"one inpainter step at batch {ti['batch_size']}: {unit['inpainter_step_cpu']:.2f} s (CPU)")
        unit["policy_step_cpu"] = policy_step_seconds(tp["model"], int(tp["train"]["batch_size"]), built["guide"])
        print(f"one policy step at batch {tp['train']['batch_size']}: {unit['policy_step_cpu']:.2f} s (CPU)")

        teacher = profile["distil_policy"]["teacher"]
        spec = teacher["planner"] + (
            ":" + ",".join(f"{k}={v}" for k, v in teacher["options"].items()) if teacher["options"] else ""
        )
        seconds, steps = episode_seconds(f"teacher={spec}", test[0], protocol)
        unit["dagger_episode"], unit["dagger_steps"] = seconds, steps
        print(f"one DAgger episode (teacher {spec}): {seconds:.1f} s, {steps} steps")

        skip = {s for s in args.skip_benchmark_planners.split(",") if s}
        per_planner = {}
        for spec in profile["benchmark"]["planners"]:
            label = parse_planner_spec(spec).label
            if label in skip:
                continue
            per_planner[label] = float(np.mean([episode_seconds(spec, maze, protocol)[0] for maze in test]))
            print(f"  benchmark episode, {label}: {per_planner[label]:.1f} s")
        mean = float(np.mean(list(per_planner.values())))
        planners = profile["benchmark"]["planners"]
        unit["benchmark_maze"] = sum(per_planner.get(parse_planner_spec(s).label, mean) for s in planners)
        unit["greedy_episode"] = per_planner.get("greedy_utility", mean)
        unit["guide_episode"] = float(np.mean([per_planner.get(k, mean) for k in ("guide", "dare")]))
    if args.save_units:
        Path(args.save_units).write_text(json.dumps(unit, indent=2) + "\n")
    print_costs(profile, unit)


def stage_costs(profile: dict, unit: dict, nodes: int, cores: int, gpus: int) -> dict[str, float]:
    """Wall seconds per stage on `nodes` x `cores` CPU cores and `gpus` GPUs (the module docstring's model)."""
    total_cores = nodes * cores
    reports = Path("reports")
    block = json.loads((reports / "block_model.json").read_text()) if (reports / "block_model.json").is_file() else {}
    drl = json.loads((reports / "drl_metrics.json").read_text()) if (reports / "drl_metrics.json").is_file() else {}
    p = profile
    episodes = p["collect_expert"]["episodes"]
    samples = episodes * unit["expert_steps"] * (1 - p["train_planner"]["train"]["val_fraction"])
    ti = p["train_inpainter"]
    inpainter_steps = p["collect_pairs"]["pairs"] * (1 - ti["val_fraction"]) / ti["batch_size"] * ti["max_epochs"]
    tp = p["train_planner"]["train"]
    policy_steps = samples / tp["batch_size"] * tp["max_epochs"]
    d = p["distil_policy"]
    dagger_episodes = d["teacher_episodes"] + d["rounds"] * d["episodes"]
    dagger_evals = d["eval_mazes"] * 2 * (d["rounds"] + 1)
    dagger_samples = dagger_episodes * unit["dagger_steps"]
    gate_mazes = p["fit_gate"]["maps"] + p["fit_gate"]["offices"]
    r = p["report"]
    report_episodes = len(r["k_values"]) * len(r["k_planners"]) * r["k_maps"]
    block_maze_epochs = (block.get("mazes_fit", 0) + block.get("mazes_holdout", 0)) * len(block.get("history", []))
    default_block_rate = block.get("train_seconds", 0.0) / max(
        1, block_maze_epochs
    )  # s per maze-epoch of the default run
    bm = p["train_block_model"]
    costs = {
        "collect_pairs": p["collect_pairs"]["pairs"] * unit["pair"] / total_cores,
        "collect_expert": episodes * unit["expert_episode"] / total_cores,
        "build_observations": episodes * unit["observations_episode"] / total_cores,
        "fit_gate": gate_mazes * unit["greedy_episode"] / total_cores,
        "train_block_model": bm["mazes"] * unit["greedy_episode"] / total_cores
        + default_block_rate * bm["mazes"] * bm["epochs"],
        "train_inpainter": inpainter_steps
        * (unit["inpainter_step_cpu"] if not gpus else ti["batch_size"] * H200_INPAINTER_S_PER_PAIR / gpus),
        "train_planner (x2)": 2
        * policy_steps
        * (unit["policy_step_cpu"] if not gpus else tp["batch_size"] * H200_POLICY_S_PER_SAMPLE / gpus),
        "distil_policy": (dagger_episodes * unit["dagger_episode"] + dagger_evals * unit["guide_episode"]) / total_cores
        + (d["rounds"] + 1)
        * dagger_samples
        * d["train"]["max_epochs"]
        * (unit["policy_step_cpu"] / d["train"]["batch_size"] if not gpus else H200_POLICY_S_PER_SAMPLE / gpus),
        # the default profile's 6,144 PPO steps (when that run trained them, not resumed), per core up to 16 environments
        "train_drl": (drl["train_seconds"] / drl["timesteps"])
        * p["train_drl"]["timesteps"]
        / max(1, min(16, total_cores) / 2)
        if drl.get("train_seconds", 0.0) > 10
        else float("nan"),
        "benchmark": p["mazes"]["test"]["count"] * unit["benchmark_maze"] / total_cores,
        "report": report_episodes * unit["guide_episode"] / total_cores,
    }
    return costs


def duration(seconds: float) -> str:
    if seconds != seconds:  # nan
        return "not measured"
    if seconds < 3600:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h" if seconds < 72 * 3600 else f"{seconds / 86400:.0f} days"


def print_costs(profile: dict, unit: dict) -> None:
    print("\nThe paper profile's wall time, by stage:\n")
    table = {name: stage_costs(profile, unit, *setting) for name, setting in SETTINGS.items()}
    stages = list(next(iter(table.values())))
    print("| stage | " + " | ".join(table) + " |")
    print("|---|" + "---:|" * len(table))
    for stage in stages:
        print(f"| {stage} | " + " | ".join(duration(table[name][stage]) for name in table) + " |")
    print(
        "| **total** | "
        + " | ".join(f"**{duration(sum(v for v in costs.values() if v == v))}**" for costs in table.values())
        + " |"
    )
    print("\nunit costs (s): " + ", ".join(f"{k} {v:.3g}" for k, v in unit.items()))


if __name__ == "__main__":
    main()
