"""The whole building: how much of what a robot can reach each planner explores on real floor plans.

Usage: python benchmarks/bench_whole_building.py [--plans data/real_plans/kth] [--planner greedy_utility ...]
                                                 [--loop simulator|session] [--lattice-only] [--starts 3]
                                                 [--workers 2] [--max-steps 6000] [--csv FILE] [--figure FILE]

Each plan of `--plans` (0.05 m PNGs with a `starts.json`, the layout of data/real_plans/kth/) is
brought to the real-robot protocol's 0.2 m cells (free only where all of a cell's pixels are,
except where the robot's centre may stand: no door it fits through is closed) and explored from
its first `--starts` start poses by each planner until the planner says it is done (the
protocol's done threshold set to 0 cells, so that no episode ends before the planner does), in
the simulator (`run_episode`) or through `ExplorationSession` in the closed loop of
`pipeline.robot.closed_loop` (SLAM maps at 0.05 m through CDR, a 0.1 m noisy pose, one goal in
twenty failing). `--lattice-only` runs the same on DARE's lattice without door nodes or the done
rule on cells: the planners as they were before the whole-building graph.

Prints per plan size (small: under 1,000 m^2 free, medium: under 3,000, big) and planner: the
episodes, the explored share of the free area a robot of the protocol's radius reaches from the
start (mean and least), the early stops (done with more than 40 m^2 of that area unseen), the
fallback decisions, the episodes the step or decision limit ended before the planner said
done, the distance and the median over episodes of each one's median decision time. `--csv`
writes one row per episode; `--figure` draws the first episode on the largest plan, door nodes and fallback
waypoints marked.
"""

from __future__ import annotations

import argparse
import csv
import json
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import torch
from PIL import Image
from tqdm import tqdm

from pipeline.planners import make_planner
from pipeline.reporting.panels import whole_building_marks
from pipeline.reporting.render import auto_scale, episode_title, render_frame, save_png
from pipeline.robot import ExplorationSession
from pipeline.robot.closed_loop import ClosedLoopConfig, run_closed_loop
from pipeline.world.maps import GroundTruthMap
from pipeline.world.protocol import PAPER_REAL_ROBOT, Protocol
from pipeline.world.resample import resample_map
from pipeline.world.simulator import final_belief, run_episode

PLAN_PIXEL_M = 0.05
TEXT_COLUMNS = ("plan", "planner", "loop", "size", "stopped")
SIZES = ((1000.0, "small"), (3000.0, "medium"), (float("inf"), "big"))  # free area (m^2) under which a plan is each


@dataclass(frozen=True)
class Task:
    plan: str
    start: int
    planner: str
    loop: str
    protocol: Protocol
    max_decisions: int


def load_plan(folder: Path, plan: str, start: dict, protocol: Protocol) -> GroundTruthMap:
    """The plan at the protocol's cell size from the start pose's pixel (`starts.json`'s row and col)."""
    image = np.asarray(Image.open(folder / f"{plan}.png"))
    fine = GroundTruthMap(
        free=image > 127,
        start_cell=(int(start["col"]), int(start["row"])),
        cell_size=PLAN_PIXEL_M,
        name=f"{plan}_{start.get('index', 0)}",
    )
    world, _ = resample_map(fine, protocol.cell_size, robot_radius_m=protocol.robot_radius_m)
    return world


def limit_reached(stopped: str) -> bool:
    """Whether an episode ended at the decision limit (session) or step limit (simulator)."""
    return stopped == "decision limit" or stopped.startswith("step limit")


def size_of(world: GroundTruthMap) -> str:
    area = world.free_cell_count * world.cell_size**2
    return next(name for limit, name in SIZES if area < limit)


def run_one(folder: str, task: Task) -> dict:
    torch.set_num_threads(1)
    starts = json.loads((Path(folder) / "starts.json").read_text())
    world = load_plan(Path(folder), task.plan, {**starts[task.plan][task.start], "index": task.start}, task.protocol)
    started = time.perf_counter()
    row = {
        "plan": task.plan,
        "start": task.start,
        "planner": task.planner,
        "loop": task.loop,
        "size": size_of(world),
        "free_m2": round(world.free_cell_count * world.cell_size**2, 1),
    }
    if task.loop == "simulator":
        result = run_episode(world, make_planner(task.planner), task.protocol)
        row.update(
            distance_m=result.distance_m,
            reachable_share=result.reachable_share,
            early_stop=result.early_stop,
            fallbacks=result.fallbacks,
            stopped=result.failure,
            violations=result.motion_violations,
            decision_ms_median=float(np.median(result.decision_ms)) if result.decision_ms else float("nan"),
        )
    else:
        session = ExplorationSession(task.planner, task.protocol)
        result = run_closed_loop(world, session, ClosedLoopConfig(max_decisions=task.max_decisions))
        row.update(
            distance_m=result.distance_m,
            reachable_share=result.reachable_share,
            early_stop=result.early_stop,
            fallbacks=result.fallbacks,
            stopped="done" if result.done else "decision limit",
            violations=0,
            decision_ms_median=float(np.median(result.decision_ms)) if result.decision_ms else float("nan"),
        )
    row["seconds"] = round(time.perf_counter() - started, 1)
    return row


def append_row(path: Path, row: dict) -> None:
    """One episode's row added to the CSV (its header first): a long run keeps what it has measured."""
    path.parent.mkdir(parents=True, exist_ok=True)
    new = not path.exists()
    with path.open("a", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(row))
        if new:
            writer.writeheader()
        writer.writerow(row)


def kept_rows(path: Path | None, tasks: list[Task]) -> list[dict]:
    """The rows of an earlier run's CSV that are episodes of `tasks`, with their numbers as numbers."""
    if path is None or not path.exists():
        return []
    wanted = {(task.plan, task.start, task.planner) for task in tasks}
    rows = []
    with path.open(newline="") as handle:
        for row in csv.DictReader(handle):
            if (row["plan"], int(row["start"]), row["planner"]) not in wanted:
                continue
            for key, value in row.items():
                if key in TEXT_COLUMNS:
                    continue
                if value in ("True", "False"):
                    row[key] = value == "True"
                else:
                    try:
                        row[key] = int(value) if value.lstrip("-").isdigit() else float(value)
                    except ValueError:
                        pass
            rows.append(row)
    return rows


def draw(folder: Path, plan: str, planner: str, protocol: Protocol, path: Path) -> None:
    """The first start's episode on `plan`, door nodes and fallback waypoints marked."""
    starts = json.loads((folder / "starts.json").read_text())
    world = load_plan(folder, plan, starts[plan][0], protocol)
    result = run_episode(world, make_planner(planner), protocol)
    doors, fallbacks = whole_building_marks(result, protocol.node_resolution)
    title = (
        episode_title(plan, planner, result.distance_m, result.steps, result.reachable_share)
        + f" of the reachable area | {len(doors)} door nodes, {result.fallbacks} fallbacks"
    )
    image = render_frame(
        world,
        final_belief(world, result.trajectory, protocol),
        result.trajectory,
        None,
        auto_scale(world.shape, 1600),
        title,
        doors=doors,
        fallbacks=fallbacks,
    )
    save_png(image, path)
    print(f"wrote {path}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--plans", type=Path, default=Path("data/real_plans/kth"))
    parser.add_argument("--planner", action="append", default=None)
    parser.add_argument("--loop", choices=("simulator", "session"), default="simulator")
    parser.add_argument(
        "--lattice-only", action="store_true", help="DARE's lattice, no door nodes, no done rule on cells"
    )
    parser.add_argument("--starts", type=int, default=3, help="start poses per plan (starts.json's first)")
    parser.add_argument("--from-start", type=int, default=0, help="the first start pose run (0: starts.json's first)")
    parser.add_argument("--resume", action="store_true", help="keep the episodes --csv already holds, run the rest")
    parser.add_argument("--only", action="append", default=None, help="run only these plans")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--max-steps", type=int, default=6000, help="waypoints (simulator) or decisions (session)")
    parser.add_argument("--csv", type=Path, default=None)
    parser.add_argument("--figure", type=Path, default=None)
    args = parser.parse_args()
    protocol = replace(
        PAPER_REAL_ROBOT,
        done_unknown_cells=0,
        max_steps=args.max_steps,
        door_graph=False if args.lattice_only else None,
    )
    starts = json.loads((args.plans / "starts.json").read_text())
    plans = [plan for plan in starts if args.only is None or plan in args.only]
    planners = args.planner or ["greedy_utility", "guide_tsp", "guide"]
    tasks = [
        Task(plan, k, name, args.loop, protocol, args.max_steps)
        for name in planners
        for plan in plans
        for k in range(args.from_start, min(args.starts, len(starts[plan])))
    ]
    rows = kept_rows(args.csv, tasks) if args.resume else []
    done = {(row["plan"], int(row["start"]), row["planner"]) for row in rows}
    todo = [task for task in tasks if (task.plan, task.start, task.planner) not in done]
    if args.csv is not None and not args.resume:
        args.csv.unlink(missing_ok=True)
    started = time.perf_counter()
    with ProcessPoolExecutor(args.workers) as pool:
        futures = [pool.submit(run_one, str(args.plans), task) for task in todo]
        for future in tqdm(as_completed(futures), total=len(futures), desc="episodes", unit="ep"):
            rows.append(future.result())
            if args.csv is not None:
                append_row(args.csv, rows[-1])
    if args.resume:
        print(f"{len(tasks) - len(todo)} episodes kept from {args.csv}")
    print(
        f"{len(tasks)} episodes ({args.loop}, {'lattice only' if args.lattice_only else 'door-aware graph'}) "
        f"in {time.perf_counter() - started:.0f} s"
    )
    print(
        f"{'size':<7} {'planner':<16} {'eps':>4} {'reach mean':>10} {'least':>7} {'early':>6} {'not done':>8} "
        f"{'fallbk':>7} {'dist m':>8} {'dec ms':>7}"
    )
    for _, size in SIZES:
        for name in planners:
            group = [r for r in rows if r["size"] == size and r["planner"] == name]
            if not group:
                continue
            share = np.array([r["reachable_share"] for r in group])
            print(
                f"{size:<7} {name:<16} {len(group):>4} {100 * share.mean():>9.1f}% {100 * share.min():>6.1f}% "
                f"{sum(r['early_stop'] for r in group):>6} {sum(limit_reached(r['stopped']) for r in group):>8} "
                f"{np.mean([r['fallbacks'] for r in group]):>7.1f} "
                f"{np.mean([r['distance_m'] for r in group]):>8.1f} "
                f"{np.median([r['decision_ms_median'] for r in group]):>7.1f}"
            )
    violations = sum(r["violations"] for r in rows)
    print(
        f"motion-rule violations: {violations}; episodes under 97 %: {sum(r['reachable_share'] < 0.97 for r in rows)}"
    )
    if args.csv is not None:
        print(f"wrote {args.csv}")
    if args.figure is not None:
        largest = max(plans, key=lambda plan: (args.plans / f"{plan}.png").stat().st_size)
        draw(args.plans, largest, planners[0], protocol, args.figure)


if __name__ == "__main__":
    main()
