"""The sliver gate from greedy episodes (the `fit_gate` stage): run `greedy_utility` on training
mazes and office floors, label every reachable target at every decision by the cells its scan
would truly reveal, fit the gate on most maps and measure it on the rest, per family. Writes the
gate, its metrics and held-out ROC curves, and logs one MLflow run in experiment "sliver_gate".
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from pydantic import model_validator

from pipeline.common.atomic import atomic_write_json
from pipeline.common.config import Section, fraction, list_of, maybe, whole
from pipeline.common.executor import run_tasks
from pipeline.common.fingerprints import files_digest, source_digest
from pipeline.common.kept_results import KeptResults
from pipeline.common.mlflow_store import import_mlflow, log_maze_set, resolve_tracking_uri
from pipeline.common.paths import CHECKPOINTS, DATA, REPORTS
from pipeline.data.gate_samples import gate_samples
from pipeline.models.defaults import PIPELINE_GATE
from pipeline.models.sliver_gate import FEATURES, fit_sliver_gate, gate_inputs, roc_auc, save_gate
from pipeline.reporting.gate_figures import gate_roc_curves
from pipeline.world.maps import list_maps, load_map
from pipeline.world.protocol import Protocol

TRAIN_MAZES = DATA.mazes_train
TRAIN_OFFICES = DATA.offices_train
GATE_PATH = PIPELINE_GATE
METRICS_PATH = REPORTS.sliver_gate
FIGURE_PATH = REPORTS.sliver_gate_figure
EXPERIMENT = "sliver_gate"
KEPT_SAMPLES = CHECKPOINTS.gate_samples


class Settings(Section):
    """The `fit_gate` section of params.yaml."""

    maps: Annotated[int, whole(1)]
    holdout_maps: Annotated[int, whole(0)]
    offices: Annotated[int, whole(0)]
    office_holdout: Annotated[int, whole(0)]
    hidden: Annotated[
        list[int],
        list_of(whole(1), min_length=0, description="a list of layer widths (whole numbers >= 1; []: logistic)"),
    ]
    fit_samples: Annotated[int | None, maybe(whole(1))] = None
    min_gain: Annotated[int, whole(0, note="cells")]
    wall_margin: Annotated[int, whole(0, note="cells")]
    threshold: Annotated[float, fraction("P(big)")]
    workers: Annotated[int, whole(1)]

    @model_validator(mode="after")
    def _holdouts_leave_maps_to_fit(self) -> "Settings":
        if not self.holdout_maps < self.maps:
            raise ValueError(f"holdout_maps ({self.holdout_maps}) must be below maps ({self.maps})")
        if self.offices and not self.office_holdout < self.offices:
            raise ValueError(f"office_holdout ({self.office_holdout}) must be below offices ({self.offices})")
        return self


def _samples(task: tuple[str, dict, int]) -> tuple[np.ndarray, np.ndarray]:
    path, protocol, wall_margin = task
    return gate_samples(load_map(path), Protocol.from_dict(protocol), wall_margin)


def collect(
    maps: list[Path], protocol: Protocol, wall_margin: int, workers: int, keep_in: Path | None = None
) -> list[tuple[np.ndarray, np.ndarray]]:
    """(counts, gains) per map, in map order; with `keep_in`, each map's kept there as it is done,
    so that a killed run takes them up again."""
    tasks = [(str(m), protocol.to_dict(), wall_margin) for m in maps]
    keep = None
    if keep_in is not None:
        identity = {"tasks": tasks, "maps": files_digest(maps), "source": source_digest()}
        keep = KeptResults(keep_in, identity)
    return run_tasks(_samples, tasks, workers, "gate samples", "maze", keep=keep)


def _shares(total: int, sizes: list[int]) -> list[int]:
    """`total` split over groups in proportion to `sizes` (largest remainders), none over its size."""
    whole = sum(sizes)
    exact = [total * size / whole for size in sizes]
    parts = [int(value) for value in exact]
    by_remainder = sorted(range(len(sizes)), key=lambda i: (parts[i] - exact[i], i))
    for i in by_remainder[: total - sum(parts)]:
        parts[i] += 1
    return parts


def _family_maps(folder: Path, count: int, holdout: int, what: str) -> list[Path]:
    """The first `count` maps of `folder`, the last `holdout` of them held out. Where the folder
    holds maps of several kinds (generated floors beside floors drawn from real plans: the file
    name before its number), each kind gives its first maps in proportion to its number, to the
    fitted maps and the held-out ones alike, so the gate sees the mix its planner will."""
    listed = list_maps(folder) if count else []
    kinds: dict[str, list[Path]] = {}
    for path in listed:
        kinds.setdefault(path.stem.rsplit("_", 1)[0], []).append(path)
    groups = list(kinds.values())
    if len(groups) <= 1:
        maps = listed[:count]
    else:
        chosen = _shares(min(count, len(listed)), [len(group) for group in groups])
        held = _shares(min(holdout, sum(chosen)), chosen)
        fitted = [path for group, n, h in zip(groups, chosen, held) for path in group[: n - h]]
        maps = fitted + [path for group, n, h in zip(groups, chosen, held) for path in group[n - h : n]]
    if count and len(maps) <= holdout:
        raise ValueError(f"{folder}: {len(maps)} maps, need more than fit_gate.{what} = {holdout}")
    return maps


def fit_gate(settings: Settings, protocol: Protocol) -> dict[str, Any]:
    """Fit, measure and write the gate from the `fit_gate` settings; the metrics written to
    reports/sliver_gate.json."""
    from sklearn.metrics import roc_curve

    s = settings
    office_holdout = s.office_holdout if s.offices else 0
    families = {  # family -> (maps, how many of the last are held out)
        "mazes": (_family_maps(TRAIN_MAZES, s.maps, s.holdout_maps, "holdout_maps"), s.holdout_maps),
        "offices": (_family_maps(TRAIN_OFFICES, s.offices, office_holdout, "office_holdout"), office_holdout),
    }
    started = time.perf_counter()
    samples = collect(
        [m for maps, _ in families.values() for m in maps], protocol, s.wall_margin, s.workers, keep_in=KEPT_SAMPLES
    )
    fit, held = [], {}  # (counts, gains) per fitted map; per family, those of its held-out maps
    for family, (maps, holdout) in families.items():
        ours, samples = samples[: len(maps)], samples[len(maps) :]
        fit += ours[: len(maps) - holdout]
        if holdout:
            held[family] = ours[len(maps) - holdout :]
    fit_gains = np.concatenate([g for _, g in fit])
    gate = fit_sliver_gate(
        np.concatenate([c for c, _ in fit]),
        fit_gains,
        s.min_gain,
        s.wall_margin,
        protocol.sensor_range_cells,
        s.threshold,
        tuple(s.hidden),
        max_samples=s.fit_samples,
    )
    metrics: dict[str, Any] = {
        "maps_fit": len(families["mazes"][0]) - s.holdout_maps,
        "maps_holdout": s.holdout_maps,
        "offices_fit": len(families["offices"][0]) - office_holdout,
        "offices_holdout": office_holdout,
        "hidden": list(s.hidden),
        "samples_fit": int(len(fit_gains)),
        "samples_drawn": int(min(len(fit_gains), s.fit_samples or len(fit_gains))),
        "big_share_fit": round(float((fit_gains >= gate.min_gain).mean()), 4),
    }
    curves = {}
    for family, maps_held in held.items():
        counts = np.concatenate([c for c, _ in maps_held])
        labels = np.concatenate([g for _, g in maps_held]) >= gate.min_gain
        probability = gate.probability(counts)
        suffix = "holdout" if family == "mazes" else f"holdout_{family}"
        metrics.update(
            {
                f"samples_{suffix}": int(len(labels)),
                f"big_share_{suffix}": round(float(labels.mean()), 4),
                f"auc_{suffix}": round(roc_auc(probability, labels), 4),
                f"accuracy_{suffix}": round(float(((probability >= gate.threshold) == labels).mean()), 4),
                f"slivers_passed_{suffix}": round(float((probability[~labels] >= gate.threshold).mean()), 4),
                f"big_passed_{suffix}": round(float((probability[labels] >= gate.threshold).mean()), 4),
            }
        )
        curves[f"gate, {family}"] = (*roc_curve(labels, probability)[:2], metrics[f"auc_{suffix}"])
        if family == "mazes":
            for k, name in enumerate(FEATURES):
                auc = round(roc_auc(gate_inputs(counts)[:, k], labels), 4)
                metrics[f"auc_holdout_{name}"] = auc
                curves[f"{name} alone, mazes"] = (*roc_curve(labels, counts[:, k])[:2], auc)
    fitted_maps = [m.name for maps, holdout in families.values() for m in maps[: len(maps) - holdout]]
    save_gate(gate, GATE_PATH, protocol.to_dict(), fitted_on={"maps": fitted_maps, **metrics})
    metrics["seconds"] = round(
        time.perf_counter() - started, 1
    )  # in the report only: the gate file is a pure function of its inputs
    atomic_write_json(METRICS_PATH, metrics)
    if curves:
        gate_roc_curves(curves, FIGURE_PATH)
    log_run(settings, protocol, metrics)
    return metrics


def log_run(settings: Settings, protocol: Protocol, metrics: dict[str, Any]) -> None:
    mlflow = import_mlflow()
    mlflow.set_tracking_uri(resolve_tracking_uri(None))
    mlflow.set_experiment(EXPERIMENT)
    with mlflow.start_run(run_name="fit_gate"):
        mlflow.log_params({**protocol.to_dict(), **{f"fit_gate.{k}": v for k, v in settings.as_written().items()}})
        log_maze_set(TRAIN_MAZES, "training")
        if settings.offices:
            log_maze_set(TRAIN_OFFICES, "training")
        mlflow.log_metrics({k: float(v) for k, v in metrics.items() if isinstance(v, (int, float))})
        for path in (GATE_PATH, METRICS_PATH, FIGURE_PATH):
            if path.is_file():
                mlflow.log_artifact(str(path))
