"""DVC stage: fit the sliver gate on greedy episodes in the training mazes.

Reads only the `fit_gate` section (maps, holdout_maps, min_gain, wall_margin, threshold,
workers) and the shared `protocol` section of params.yaml. Runs `greedy_utility` on the
first `maps` training mazes, labels every reachable target at every decision by the cells
its scan would truly reveal, fits the logistic gate (`pipeline.sliver_gate`) on all but the
last `holdout_maps` mazes and measures it on those. Writes models/sliver_gate/sliver_gate.json,
reports/sliver_gate.json (sample counts, held-out ROC AUC of the gate and of each count
alone, held-out accuracy at the gate's threshold) and reports/sliver_gate.png (held-out ROC
curves). Logs one MLflow run in experiment "sliver_gate".
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.maps import list_maps, load_map
from pipeline.parallel import map_with_progress
from pipeline.params_file import load_params, params_section
from pipeline.protocol import Protocol
from pipeline.sliver_gate import FEATURES, fit_sliver_gate, gate_inputs, roc_auc, save_gate
from pipeline.stage_errors import run_stage_main

TRAIN_MAZES = Path("data/mazes/train")
GATE_PATH = Path("models/sliver_gate/sliver_gate.json")
METRICS_PATH = Path("reports/sliver_gate.json")
FIGURE_PATH = Path("reports/sliver_gate.png")
EXPERIMENT = "sliver_gate"
DEFAULTS: dict[str, Any] = {"maps": 48, "holdout_maps": 12, "min_gain": 50, "wall_margin": 2, "threshold": 0.5,
                            "workers": 2}


def read_params(params_path: str | Path) -> tuple[dict[str, Any], Protocol]:
    params = load_params(params_path)
    section = dict(params_section(params, "fit_gate", params_path))
    unknown = sorted(set(section) - set(DEFAULTS))
    if unknown:
        raise ValueError(f"{params_path}: unknown fit_gate parameter(s) {unknown}; known: {sorted(DEFAULTS)}")
    section = {**DEFAULTS, **section}
    for key in ("maps", "holdout_maps", "min_gain", "wall_margin", "workers"):
        value = section[key]
        if isinstance(value, bool) or not isinstance(value, int) or value < (1 if key in ("maps", "workers") else 0):
            raise ValueError(f"{params_path}: fit_gate.{key} must be a whole number, got {value!r}")
    if not section["holdout_maps"] < section["maps"]:
        raise ValueError(f"{params_path}: fit_gate.holdout_maps must be below fit_gate.maps")
    return section, Protocol.from_dict(params.get("protocol") or {})


def _samples(task: tuple[str, dict, int]) -> tuple[np.ndarray, np.ndarray]:
    from pipeline.gate_samples import gate_samples

    path, protocol, wall_margin = task
    return gate_samples(load_map(path), Protocol.from_dict(protocol), wall_margin)


def collect(maps: list[Path], protocol: Protocol, wall_margin: int, workers: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """(counts, gains) per map, in map order."""
    tasks = [(str(m), protocol.to_dict(), wall_margin) for m in maps]
    return map_with_progress(_samples, tasks, workers, "gate samples", "maze")


def roc_figure(curves: dict[str, tuple[np.ndarray, np.ndarray, float]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 4.5))
    for name, (fpr, tpr, auc) in curves.items():
        ax.plot(fpr, tpr, label=f"{name} (AUC {auc:.3f})", lw=2 if name == "gate" else 1)
    ax.plot([0, 1], [0, 1], color="0.7", lw=0.8, ls="--")
    ax.set(xlabel="slivers passed (false positive rate)", ylabel="big targets passed (true positive rate)",
           title="Sliver gate on held-out training mazes")
    ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(params_path: str = "params.yaml") -> dict[str, Any]:
    """Fit, measure and write the gate; returns the metrics written to reports/sliver_gate.json."""
    from sklearn.metrics import roc_curve

    section, protocol = read_params(params_path)
    maps = list_maps(TRAIN_MAZES)[: section["maps"]]
    if len(maps) <= section["holdout_maps"]:
        raise ValueError(f"{TRAIN_MAZES}: {len(maps)} maps, need more than fit_gate.holdout_maps = {section['holdout_maps']}")
    started = time.perf_counter()
    per_map = collect(maps, protocol, section["wall_margin"], section["workers"])
    split = len(maps) - section["holdout_maps"]
    fit_counts = np.concatenate([c for c, _ in per_map[:split]])
    fit_gains = np.concatenate([g for _, g in per_map[:split]])
    gate = fit_sliver_gate(fit_counts, fit_gains, section["min_gain"], section["wall_margin"],
                           protocol.sensor_range_cells, section["threshold"])
    metrics: dict[str, Any] = {
        "maps_fit": split, "maps_holdout": section["holdout_maps"], "samples_fit": int(len(fit_gains)),
        "big_share_fit": round(float((fit_gains >= gate.min_gain).mean()), 4),
        "coef": dict(zip(FEATURES, (round(c, 4) for c in gate.coef))), "intercept": round(gate.intercept, 4),
    }
    curves = {}
    if section["holdout_maps"]:
        counts = np.concatenate([c for c, _ in per_map[split:]])
        labels = np.concatenate([g for _, g in per_map[split:]]) >= gate.min_gain
        probability = gate.probability(counts)
        metrics.update(samples_holdout=int(len(labels)), big_share_holdout=round(float(labels.mean()), 4),
                       auc_holdout=round(roc_auc(probability, labels), 4),
                       accuracy_holdout=round(float(((probability >= gate.threshold) == labels).mean()), 4),
                       slivers_passed_holdout=round(float((probability[~labels] >= gate.threshold).mean()), 4),
                       big_passed_holdout=round(float((probability[labels] >= gate.threshold).mean()), 4))
        curves["gate"] = (*roc_curve(labels, probability)[:2], metrics["auc_holdout"])
        for k, name in enumerate(FEATURES):
            auc = round(roc_auc(gate_inputs(counts)[:, k], labels), 4)
            metrics[f"auc_holdout_{name}"] = auc
            curves[f"{name} alone"] = (*roc_curve(labels, counts[:, k])[:2], auc)
    save_gate(gate, GATE_PATH, protocol.to_dict(), fitted_on={"maps": [m.name for m in maps[:split]], **metrics})
    metrics["seconds"] = round(time.perf_counter() - started, 1)  # in the report only: the gate file is a pure function of its inputs
    METRICS_PATH.parent.mkdir(parents=True, exist_ok=True)
    METRICS_PATH.write_text(json.dumps(metrics, indent=2) + "\n")
    if curves:
        roc_figure(curves, FIGURE_PATH)
    log_run(section, protocol, metrics)
    print(json.dumps(metrics, indent=2))
    return metrics


def log_run(section: dict[str, Any], protocol: Protocol, metrics: dict[str, Any]) -> None:
    from pipeline.tracking import import_mlflow, resolve_tracking_uri

    mlflow = import_mlflow()
    mlflow.set_tracking_uri(resolve_tracking_uri(None))
    mlflow.set_experiment(EXPERIMENT)
    with mlflow.start_run(run_name="fit_gate"):
        mlflow.log_params({**protocol.to_dict(), **{f"fit_gate.{k}": v for k, v in section.items()}})
        mlflow.log_metrics({k: float(v) for k, v in metrics.items() if isinstance(v, (int, float))})
        for path in (GATE_PATH, METRICS_PATH, FIGURE_PATH):
            if path.is_file():
                mlflow.log_artifact(str(path))


if __name__ == "__main__":
    run_stage_main(main)
