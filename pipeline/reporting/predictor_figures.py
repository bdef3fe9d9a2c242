"""Figures of the Table I evaluation: precision and V_u size against tau, and Fig. 3's panels
(observed nodes | V_p | V_u after region evaluation, predictions coloured by the ground truth)."""

from __future__ import annotations

from pathlib import Path
from typing import cast

import cv2
import numpy as np
import pandas as pd

from pipeline.common.atomic import atomic_file
from pipeline.evaluation.predictor_eval import (
    PAPER_PRECISION,
    Checkpoint,
    InpaintFactory,
    Prediction,
    _resolve_inpaint,
    explore_checkpoints,
    free_in_truth,
    predict_at,
)
from pipeline.lattice.graph import NODE_FREE, NODE_OCCUPIED
from pipeline.prediction.global_graph import CENTROID, KNOWN, GlobalGraphConfig
from pipeline.prediction.node_predictor import InpaintFn, NodePredictor, NodePredictorConfig
from pipeline.reporting.render import PANEL_GAP_RGB, auto_scale, render_frame, render_header, save_png
from pipeline.world.maps import GroundTruthMap, load_map
from pipeline.world.protocol import Protocol, protocol_for_map


def plot_threshold_sweep(sweep: pd.DataFrame, out_path: str | Path) -> Path:
    """Two panels over tau, one line per step: precision of V_u (the paper's Table I dashed) and
    V_u nodes per map."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_p, ax_n) = plt.subplots(1, 2, figsize=(10, 4))
    for i, (step, group) in enumerate(sweep.groupby("step", sort=True)):
        group = group.sort_values("threshold")
        colour = f"C{i}"
        ax_p.plot(group.threshold, 100 * group.precision, "o-", color=colour, label=f"step {step}")
        if step in PAPER_PRECISION:
            ax_p.axhline(PAPER_PRECISION[step], color=colour, linestyle="--", linewidth=0.8)
        ax_n.plot(group.threshold, group.nodes_per_map, "o-", color=colour, label=f"step {step}")
    ax_p.set(xlabel="tau", ylabel="precision of V_u (%)", title="precision (dashed: paper, Table I)")
    ax_n.set(xlabel="tau", ylabel="V_u nodes per map", title="what the planners get", yscale="log")
    ax_p.legend(fontsize=8)
    ax_p.grid(alpha=0.3)
    ax_n.grid(alpha=0.3)
    fig.tight_layout()
    out_path = Path(out_path)
    with atomic_file(out_path) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)
    return out_path


# ----------------------------------------------------------------------------- Fig. 3
FREE_NODE_RGB = (40, 110, 230)
OBSTACLE_NODE_RGB = (20, 20, 20)
TRUE_PRED_RGB = (30, 170, 60)
FALSE_PRED_RGB = (230, 40, 40)
CENTROID_RGB = (255, 150, 0)


def _panel(base: np.ndarray, title: str) -> np.ndarray:
    header = render_header(base.shape[1], title, legend=False)
    return base if header is None else np.concatenate([header, base], axis=0)


def _centre(cells: np.ndarray, scale: int) -> list[tuple[int, int]]:
    pts = np.round((np.asarray(cells, dtype=np.float64).reshape(-1, 2) + 0.5) * scale).astype(int)
    return [cast(tuple[int, int], tuple(map(int, p))) for p in pts]


def _dots(img: np.ndarray, cells: np.ndarray, scale: int, colour, radius: int, outline: bool = True) -> None:
    for c in _centre(cells, scale):
        if outline:
            cv2.circle(img, c, radius + 1, (255, 255, 255), -1, cv2.LINE_AA)
        cv2.circle(img, c, radius, colour, -1, cv2.LINE_AA)


def render_prediction_figure(
    ground_truth: GroundTruthMap, checkpoint: Checkpoint, prediction: Prediction, scale: int | None = None
) -> np.ndarray:
    """Fig. 3-style RGB image: observed nodes | V_p | V_u after region evaluation (with centroids).

    Predicted nodes are green where free in the ground truth and red where not; centroids orange.
    """
    episode, lattice = checkpoint.episode, checkpoint.lattice
    scale = scale or max(2, auto_scale(ground_truth.shape, target_px=420))
    radius = max(2, int(round(1.2 * scale)))

    def background() -> np.ndarray:
        return render_frame(ground_truth, episode.belief.grid, episode.trajectory, None, scale, "", legend=False).copy()

    def predicted_dots(img: np.ndarray, ids: np.ndarray) -> None:
        free = free_in_truth(lattice, ground_truth, ids)
        _dots(img, lattice.node_cells[ids[free]], scale, TRUE_PRED_RGB, radius)
        _dots(img, lattice.node_cells[ids[~free]], scale, FALSE_PRED_RGB, radius)

    observed = background()
    _dots(observed, lattice.node_cells[lattice.node_state == NODE_FREE], scale, FREE_NODE_RGB, radius)
    _dots(observed, lattice.node_cells[lattice.node_state == NODE_OCCUPIED], scale, OBSTACLE_NODE_RGB, radius)

    vp = background()
    _dots(vp, lattice.node_cells[lattice.node_state == NODE_FREE], scale, FREE_NODE_RGB, max(1, radius - 1), False)
    predicted_dots(vp, prediction.predicted)

    vu = background()
    gg = prediction.global_graph
    _dots(vu, lattice.node_cells[gg.lattice_ids[gg.types == KNOWN]], scale, FREE_NODE_RGB, max(1, radius - 1), False)
    kept = prediction.kept
    predicted_dots(vu, kept)
    centroid_cells = lattice.spec.world_to_cell(gg.positions[gg.types == CENTROID])
    for c in _centre(centroid_cells, scale):
        cv2.circle(vu, c, 2 * radius + 1, (20, 20, 20), -1, cv2.LINE_AA)
        cv2.circle(vu, c, 2 * radius, CENTROID_RGB, -1, cv2.LINE_AA)

    def precision_text(ids: np.ndarray) -> str:
        if ids.size == 0:
            return "none"
        return f"{int(free_in_truth(lattice, ground_truth, ids).sum())}/{ids.size} free"

    panels = [
        _panel(observed, f"step {checkpoint.step}: observed nodes (blue free, black obstacle)"),
        _panel(vp, f"V_p: {precision_text(prediction.predicted)} (green free, red not)"),
        _panel(vu, f"V_u: {precision_text(kept)}, {int((gg.types == CENTROID).sum())} centroids (orange)"),
    ]
    height = max(p.shape[0] for p in panels)
    gap = np.empty((height, 8, 3), dtype=np.uint8)
    gap[:] = PANEL_GAP_RGB
    row = []
    for i, p in enumerate(panels):
        if p.shape[0] < height:
            pad = np.empty((height - p.shape[0], p.shape[1], 3), dtype=np.uint8)
            pad[:] = PANEL_GAP_RGB
            p = np.concatenate([p, pad], axis=0)
        row.extend([gap, p] if i else [p])
    return np.ascontiguousarray(np.concatenate(row, axis=1))


def prediction_figure(
    map_path: str | Path,
    step: int,
    inpaint_fn: InpaintFn | None = None,
    predictor_config: NodePredictorConfig = NodePredictorConfig(),
    graph_config: GlobalGraphConfig = GlobalGraphConfig(),
    protocol: Protocol = Protocol(),
    *,
    inpaint_for: InpaintFactory | None = None,
    out_path: str | Path | None = None,
    scale: int | None = None,
    start: tuple[float, float] | None = None,
) -> np.ndarray | None:
    """Explore one map to `step` and draw its Fig. 3 panels (saved with save_png when `out_path`).

    Returns None when the exploration ends before `step`.
    """
    factory = _resolve_inpaint(inpaint_fn, inpaint_for)
    ground_truth = load_map(map_path, start=start, cell_size=protocol.cell_size)
    map_protocol = protocol_for_map(protocol, ground_truth, map_path)
    for checkpoint in explore_checkpoints(ground_truth, [step], map_protocol):
        predictor = NodePredictor(factory(ground_truth, checkpoint.lattice), predictor_config)
        prediction = predict_at(checkpoint, predictor, graph_config)
        image = render_prediction_figure(ground_truth, checkpoint, prediction, scale)
        if out_path is not None:
            save_png(image, out_path)
        return image
    return None
