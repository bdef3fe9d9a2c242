"""Real-robot models trained with real floor plans, measured on plans they never saw: folds by building.

Usage: python benchmarks/real_plan_folds.py [--fold all] [--fold f1] [--fold f2] [--out runs/folds]
                                            [--plans data/real_plans/kth] [--share 0.25] [--train-only]
                                            [--planner greedy_utility ...] [--starts-small 3] [--workers 2]
       python benchmarks/real_plan_folds.py --baseline REV [--out runs/folds] ...   # models shipped at REV instead

Each fold runs, in its own folder OUT/<fold>/ (its own data/, models/, checkpoints/), the stages of
`profiles/real_robot.yaml` that make the models a real-robot planner picks: import_plans,
generate_mazes (`--share` of the training floors drawn from the plans, never from the fold's
held-out plans: `mazes.train.plans_exclude`), collect_pairs, train_inpainter, collect_expert,
build_observations, train_planner (guide, dare) and fit_gate. The DRL policy and the block model
are trained on generated mazes alone, so no fold retrains them. Fold `all` leaves no plan out:
`--ship` copies its models into pipeline/assets/real_robot/.

The folds split the 14 KTH plans by building (plans whose numbers run on, of one footprint, are
floors of one building, so a plan of a building another fold trained on is no held-out plan):
`f1` holds out 50010535/50010536 (three floors) and 50052748-50 (three), `f2` 50015847-48,
50037764-65 and 50052751-54.

Then the fold's models explore its held-out plans (`guide benchmark` in the fold's folder, so
that the planners pick its models/) at the real-robot protocol: the plans at 0.2 m with the
import's start poses, 3 per plan under 1,000 m^2 free (`--starts-small`), 1 on the larger ones,
plans over 3,000 m^2 (the two largest, 4,200-4,400 m^2) left out (`--max-free-m2`).
`--baseline REV` runs the same episodes of every fold in OUT/baseline/ with the real-robot models
shipped at git revision REV (trained on generated floors alone before the plans joined them). Each fold's summary.md pairs every planner with
`greedy_utility`; the script prints a planner x fold table of those paired differences.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import yaml

from pipeline.evaluation.statistics import paired_difference
from pipeline.world.protocol import PAPER_REAL_ROBOT

REPO = Path(__file__).resolve().parents[1]
PROFILE = REPO / "profiles" / "real_robot.yaml"
FOLDS: dict[str, tuple[str, ...]] = {
    "all": (),
    "f1": ("50010535_PLAN1", "50010535_PLAN2", "50010536_PLAN3", "50052748", "50052749", "50052750"),
    "f2": ("50015847", "50015848", "50037764_PLAN1", "50037765_PLAN3", "50052751", "50052752", "50052753", "50052754"),
}
STAGES = (
    ["import_plans"],
    ["generate_mazes"],
    ["collect_pairs"],
    ["train_inpainter"],
    ["collect_expert"],
    ["build_observations"],
    ["train_planner", "--variant", "guide"],
    ["train_planner", "--variant", "dare"],
    ["fit_gate"],
)
SHIPPED = {  # the fold's model file -> its name in pipeline/assets/real_robot/
    "models/inpainter/inpainter.pt": "inpainter.pt",
    "models/planner_guide/policy.pt": "planner_guide.pt",
    "models/planner_dare/policy.pt": "planner_dare.pt",
    "models/sliver_gate/sliver_gate.json": "sliver_gate.json",
}
SMALL_M2 = 1000.0  # a plan under this free area gets --starts-small start poses, a larger one 1
PLANNERS = ("greedy_utility", "gated=greedy_utility:sliver_gate=true", "guide", "guide_tsp", "guide_noregion", "mapex")


def shipped_models(rev: str, folder: Path) -> None:
    """The real-robot models shipped at git revision `rev`, written where a planner run in `folder`
    looks for the pipeline's models first."""
    for target, name in SHIPPED.items():
        blob = subprocess.run(
            ["git", "show", f"{rev}:pipeline/assets/real_robot/{name}"], cwd=REPO, capture_output=True, check=True
        ).stdout
        (folder / target).parent.mkdir(parents=True, exist_ok=True)
        (folder / target).write_bytes(blob)


def fold_params(held_out: tuple[str, ...], share: float, plans: Path) -> dict:
    """The real-robot profile with the fold's plan mix and held-out plans."""
    params = yaml.safe_load(PROFILE.read_text(encoding="utf-8"))
    params["mazes"]["train"]["plans_share"] = share
    params["mazes"]["train"]["plans_exclude"] = list(held_out)
    params["plans"]["source"] = str(plans.resolve())
    return params


def run_stages(folder: Path, params: dict) -> None:
    """The model stages in `folder`, each skipped once it finished with these params."""
    folder.mkdir(parents=True, exist_ok=True)
    text = yaml.safe_dump(params, sort_keys=False)
    params_file = folder / "params.yaml"
    if params_file.exists() and params_file.read_text(encoding="utf-8") != text:
        shutil.rmtree(folder / ".done", ignore_errors=True)  # other settings: every stage again
    params_file.write_text(text, encoding="utf-8")
    env = {**os.environ, "PYTHONPATH": f"{REPO}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    env.setdefault("MLFLOW_TRACKING_URI", f"sqlite:///{(folder / 'mlflow.db').resolve()}")
    for stage in STAGES:
        marker = folder / ".done" / "-".join(stage)
        if marker.exists():
            continue
        print(f"[{folder.name}] {' '.join(stage)}", flush=True)
        subprocess.run([sys.executable, "-m", f"stages.{stage[0]}", *stage[1:]], cwd=folder, env=env, check=True)
        marker.parent.mkdir(exist_ok=True)
        marker.touch()


def held_out_maps(plans_dir: Path, held_out: tuple[str, ...], out: Path, starts_small: int, max_free_m2: float) -> Path:
    """ROS maps of the held-out plans of at most `max_free_m2` free, one per start pose of the
    import's (`starts_small` on plans under SMALL_M2, 1 on larger ones)."""
    manifest = {plan["name"]: plan for plan in json.loads((plans_dir / "manifest.json").read_text())["plans"]}
    out.mkdir(parents=True, exist_ok=True)
    for name in held_out:
        plan = manifest[name]
        if plan["free_m2"] > max_free_m2:
            continue
        shutil.copyfile(plans_dir / f"{name}.pgm", out / f"{name}.pgm")
        base = yaml.safe_load((plans_dir / f"{name}.yaml").read_text())
        count = starts_small if plan["free_m2"] < SMALL_M2 else 1
        for k, start in enumerate(plan["starts_m"][:count]):  # the manifest's starts in map metres
            (out / f"{name}_s{k}.yaml").write_text(yaml.safe_dump({**base, "start": start}, sort_keys=False))
    return out


def benchmark(folder: Path, maps: Path, planners: list[str], workers: int) -> Path:
    """`guide benchmark` of the held-out maps at the real-robot protocol, run in `folder`."""
    p = PAPER_REAL_ROBOT
    out = folder / "heldout_bench"
    command = ["guide", "benchmark", "--maps", str(maps.resolve()), "--out", str(out.resolve())]
    for planner in planners:
        command += ["--planner", planner]
    command += [
        "--workers", str(workers), "--no-mlflow", "--node-resolution", str(p.node_resolution),
        "--sensor-range", str(p.sensor_range), "--utility-range", str(p.utility_range),
        "--region-size", str(p.region_size), "--done-unknown-cells", str(p.done_unknown_cells),
        "--max-steps", str(p.max_steps), "--robot-radius", str(p.robot_radius_m),
    ]  # fmt: skip
    subprocess.run(command, cwd=folder, check=False)
    return out


def paired_rows(bench: Path, baseline: str = "greedy_utility") -> dict[str, tuple[float, float, float, int]]:
    """Per planner: (mean distance, paired % against the baseline, its 95 % half-width, maps)."""
    import pandas as pd

    frame = pd.read_csv(bench / "metrics.csv")
    rows = {}
    for planner in sorted(frame["planner"].unique()):
        mean, half, maps = paired_difference(frame, planner, baseline)
        rows[planner] = (float(frame[frame["planner"] == planner]["distance_m"].mean()), 100 * mean, 100 * half, maps)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fold", action="append", choices=sorted(FOLDS), default=None)
    parser.add_argument("--out", type=Path, default=Path("runs/folds"))
    parser.add_argument("--plans", type=Path, default=REPO / "data" / "real_plans" / "kth")
    parser.add_argument("--share", type=float, default=0.25, help="share of the training floors drawn from the plans")
    parser.add_argument("--train-only", action="store_true")
    parser.add_argument(
        "--baseline",
        metavar="REV",
        default=None,
        help="the models shipped at git revision REV on the folds' held-out plans",
    )
    parser.add_argument("--ship", action="store_true", help="copy fold all's models to pipeline/assets/real_robot/")
    parser.add_argument("--planner", action="append", default=None)
    parser.add_argument("--starts-small", type=int, default=3)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument(
        "--max-free-m2", type=float, default=3000.0, help="benchmark held-out plans up to this free area"
    )
    args = parser.parse_args()
    folds = args.fold or ["f1", "f2"]
    planners = args.planner or list(PLANNERS)
    table: dict[str, dict[str, tuple[float, float, float, int]]] = {}
    for fold in folds:
        held_out = FOLDS[fold]
        folder = args.out / ("baseline" if args.baseline else fold)
        if args.baseline:
            shipped_models(args.baseline, folder)
            plans_dir = args.out / fold / "data" / "plans"
        else:
            run_stages(folder, fold_params(held_out, args.share, args.plans))
            plans_dir = folder / "data" / "plans"
        if fold == "all" and args.ship:
            assets = REPO / "pipeline" / "assets" / "real_robot"
            for source, name in SHIPPED.items():
                shutil.copyfile(folder / source, assets / name)
            print(f"shipped {len(SHIPPED)} models to {assets}")
        if args.train_only or not held_out:
            continue
        maps = held_out_maps(plans_dir, held_out, folder / f"heldout_{fold}", args.starts_small, args.max_free_m2)
        bench = benchmark(folder, maps, planners, args.workers)
        if args.baseline:
            shutil.rmtree(folder / f"heldout_bench_{fold}", ignore_errors=True)
            bench = bench.rename(folder / f"heldout_bench_{fold}")
        table[fold] = paired_rows(bench)
    if table:
        print("| planner | " + " | ".join(f"{fold} (m, vs greedy_utility)" for fold in table) + " |")
        print("|---|" + "---:|" * len(table))
        names = sorted({name for rows in table.values() for name in rows})
        for name in names:
            cells = []
            for rows in table.values():
                mean, pct, half, maps = rows.get(name, (float("nan"), float("nan"), float("nan"), 0))
                cells.append(f"{mean:.1f}, {pct:+.1f} % +- {half:.1f} ({maps})")
            print(f"| {name} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
