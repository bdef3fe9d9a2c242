"""Planners that use predicted free nodes V_p without a learned policy.

- `guide_tsp`: the GUIDE paper's "w/o diffusion" ablation. Every decision: update the
  lattice graph, predict V_p (Global Node Predictor), build the region-evaluated global
  graph (known + kept predicted nodes + centroids, boosted utilities), sample target nodes
  by boosted utility (the `top_k` known useful nodes, best first, skipping any within
  `spread` metres of one already chosen), order them by an open TSP path from the robot
  over shortest-path distances *on the global graph* (so predicted nodes shape the
  distances and the order), and take one lattice step toward the first target along the
  shortest path on the *known* lattice graph. Re-plan at every step.
- `mapex`: after MapEx (Ho et al., 2024). Candidate viewpoints are the useful nodes
  (unvisited known free nodes that see frontier). The predicted map is the belief with a
  disc of radius node_resolution / 2 painted free around every predicted node (unknown
  cells only). A candidate's gain counts the unknown cells that its ray fan (the graph
  utility's fan, `utility_range`) reaches through belief-free or predicted-free cells and
  that are predicted free (minus cells within `wall_margin` cells of a known obstacle: the
  inside of a wall whose face was seen is never observed, and counting it made the robot
  come back for it), plus its frontier utility on the observed map (what it would
  see anyway, so that with no prediction `mapex` is `greedy_utility`). Score = gain / path
  cost on the known graph; one lattice step toward the best. MapEx weights its gain by
  the variance of an ensemble of predictors; we have a single predictor and no variance,
  so the gain is unweighted.

Motion rule: both planners return a single waypoint, the next node on a shortest path of
the lattice graph's known-free edges (`self.graph`); predicted edges only change which
target is chosen, never the path driven.

Predictor: an `inpaint` callable (uint8 node image -> free probability; tests pass an
oracle) wins; else a `checkpoint` path, else `models/inpainter/inpainter.pt` when it exists,
loaded once per process (module-level cache) and run through `TracedInpainter`. With none,
nothing is predicted and both planners reduce to their frontier-only versions (the
instance's `description` says which predictor is in use).
"""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Callable

import cv2
import numpy as np
from scipy.sparse.csgraph import dijkstra

from pipeline.global_graph import KNOWN, GlobalGraph, GlobalGraphConfig
from pipeline.graph import visible_counts
from pipeline.maps import GroundTruthMap
from pipeline.node_predictor import NodePredictor, NodePredictorConfig
from pipeline.planners.base import GraphPlanner, Waypoint, register_planner
from pipeline.planners.tare import tsp_path
from pipeline.protocol import Protocol
from pipeline.sensor import FREE, OCCUPIED, UNKNOWN
from pipeline.simulator import Observation

DEFAULT_CHECKPOINT = Path("models/inpainter/inpainter.pt")
InpaintFn = Callable[[np.ndarray], np.ndarray]

_MODEL_CACHE: dict[str, InpaintFn] = {}
_MODEL_LOCK = threading.Lock()


def cached_inpainter(path: str | Path) -> InpaintFn:
    """The trained inpainter at `path` as a node image -> probability function, loaded once per process."""
    key = str(Path(path).resolve())
    with _MODEL_LOCK:
        if key not in _MODEL_CACHE:
            import torch

            from pipeline.models.modeling_inpainter import TracedInpainter
            from pipeline.training.inpainter import load_inpainter

            torch.set_num_threads(max(1, min(2, torch.get_num_threads())))
            model, _ = load_inpainter(path)
            _MODEL_CACHE[key] = TracedInpainter(model).predict
    return _MODEL_CACHE[key]


def resolve_inpainter(inpaint: InpaintFn | None, checkpoint: str | None) -> tuple[InpaintFn | None, str]:
    """(inpaint function or None, a few words saying which predictor is used)."""
    if inpaint is not None:
        return inpaint, "injected inpainter"
    if checkpoint is not None:
        if not Path(checkpoint).is_file():
            raise FileNotFoundError(f"{checkpoint}: no inpainter checkpoint there")
        return cached_inpainter(checkpoint), f"trained inpainter {checkpoint}"
    if DEFAULT_CHECKPOINT.is_file():
        return cached_inpainter(DEFAULT_CHECKPOINT), f"trained inpainter {DEFAULT_CHECKPOINT}"
    return None, "no inpainter found: nothing predicted (frontier-only fallback)"


class _PredictingPlanner(GraphPlanner):
    """A lattice-graph planner with a node predictor (or none)."""

    base_description = ""

    def __init__(
        self,
        min_utility: int = 2,
        checkpoint: str | None = None,
        inpaint: InpaintFn | None = None,
        threshold: float = 0.5,
        min_component: int = 3,
    ):
        super().__init__(min_utility=min_utility)
        fn, source = resolve_inpainter(inpaint, checkpoint)
        self.predictor = None if fn is None else NodePredictor(fn, NodePredictorConfig(threshold, int(min_component)))
        self.predictor_source = source
        self.description = f"{self.base_description} [{source}]"
        self.last_decision: dict = {}

    def predict(self) -> np.ndarray:
        if self.predictor is None or self.graph is None:
            return np.zeros(0, dtype=np.int64)
        return self.predictor.predict(self.graph)

    def reachable_useful(self, robot: int, dist: np.ndarray) -> np.ndarray:
        targets = self.useful_nodes()
        return targets[np.isfinite(dist[targets]) & (targets != robot)]


@register_planner("guide_tsp")
class GuideTspPlanner(_PredictingPlanner):
    """GUIDE without the diffusion policy: utility-sampled targets ordered by a TSP path on the global graph."""

    base_description = (
        "GUIDE w/o diffusion: top-k boosted-utility targets of the global graph (predicted nodes), "
        "open TSP over global-graph distances, one known-graph step to the first"
    )
    description = base_description

    def __init__(
        self,
        min_utility: int = 2,
        checkpoint: str | None = None,
        inpaint: InpaintFn | None = None,
        top_k: int = 12,  # dev mazes (6 x 100 m, oracle): k=12 / 12 m 518 m mean, k=8 / 8 m 535 m, k=4 / 8 m 603 m
        spread: float = 12.0,
        exact_max: int = 8,
        max_moves: int = 100,
        global_graph: GlobalGraphConfig = GlobalGraphConfig(),
        threshold: float = 0.5,
        min_component: int = 3,
    ):
        super().__init__(min_utility, checkpoint, inpaint, threshold, min_component)
        if top_k < 1:
            raise ValueError(f"top_k must be >= 1, got {top_k}")
        self.top_k = int(top_k)
        self.spread = float(spread)
        self.exact_max = int(exact_max)
        self.max_moves = int(max_moves)
        self.global_config = global_graph

    def reset(self, ground_truth: GroundTruthMap, protocol: Protocol, seed: int) -> None:
        super().reset(ground_truth, protocol, seed)
        assert self.graph is not None
        self.global_graph = GlobalGraph(self.graph, self.global_config)

    def select_targets(self, candidates: np.ndarray, utility: np.ndarray, dist: np.ndarray) -> np.ndarray:
        """Up to top_k candidates, highest utility first (nearer on a tie), none within `spread` of another."""
        graph = self.graph
        assert graph is not None
        order = np.lexsort((candidates, dist[candidates], -utility))
        chosen: list[int] = []
        xy = graph.node_world
        for k in order:
            node = int(candidates[k])
            if chosen and np.hypot(*(xy[chosen] - xy[node]).T).min() < self.spread:
                continue
            chosen.append(node)
            if len(chosen) >= self.top_k:
                break
        return np.array(chosen, dtype=np.int64)

    def plan(self, observation: Observation) -> list[Waypoint]:
        graph = self.update_graph(observation)
        robot = self.robot_node(observation)
        dist, pred = graph.shortest_paths(robot)
        candidates = self.reachable_useful(robot, dist)
        if candidates.size == 0:
            return []
        predicted = self.predict()
        gg = self.global_graph
        gg.update(observation.belief, observation.position, predicted, self.visited)
        known_ids = gg.lattice_ids[gg.types == KNOWN]  # sorted: the first rows of the global graph
        rows = np.searchsorted(known_ids, candidates)
        utility = gg.utility[rows]
        targets = self.select_targets(candidates, utility, dist)
        target_rows = np.searchsorted(known_ids, targets)
        robot_row = int(np.searchsorted(known_ids, robot))
        points = np.concatenate([[robot_row], target_rows])
        d = dijkstra(gg.adjacency, directed=False, indices=points)[:, points]
        d = np.minimum(d, d.T)
        if not np.isfinite(d).all():  # cannot happen (known edges are in the global graph); be safe
            d = np.where(np.isfinite(d), d, 1e6)
        order = tsp_path(d, None, self.exact_max, self.max_moves)
        tour = [int(targets[k - 1]) for k in order[1:]]
        first = tour[0]
        self.last_decision = {"targets": targets, "tour": tour, "predicted": int(len(predicted))}
        return self.waypoints_along(graph.path_from_predecessors(pred, first))


@register_planner("mapex")
class MapExPlanner(_PredictingPlanner):
    """MapEx-style: information gain on the predicted map per metre of path, best viewpoint first."""

    base_description = (
        "MapEx (Ho 2024): frontier viewpoints scored by gain on the predicted map (predicted-free "
        "unknown cells in the ray fan, unweighted: no ensemble variance) over path cost"
    )
    description = base_description

    def __init__(
        self,
        min_utility: int = 2,
        checkpoint: str | None = None,
        inpaint: InpaintFn | None = None,
        wall_margin: int = 2,
        threshold: float = 0.5,
        min_component: int = 3,
    ):
        super().__init__(min_utility, checkpoint, inpaint, threshold, min_component)
        if wall_margin < 0:
            raise ValueError(f"wall_margin must be >= 0, got {wall_margin}")
        self.wall_margin = int(wall_margin)

    def predicted_free_cells(self, belief: np.ndarray, predicted: np.ndarray) -> np.ndarray:
        """Unknown cells within node_resolution / 2 of a predicted node."""
        graph = self.graph
        assert graph is not None
        painted = np.zeros(belief.shape, dtype=np.uint8)
        if predicted.size == 0:
            return painted.astype(bool)
        cells = graph.node_cells[predicted]
        painted[cells[:, 1], cells[:, 0]] = 1
        radius = int(round(graph.spec.node_step_cells / 2))
        kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
        painted = cv2.dilate(painted, kernel).astype(bool) & (belief == UNKNOWN)
        if self.wall_margin > 0:  # unknown cells just behind a seen wall face are its inside, not free space
            m = 2 * self.wall_margin + 1
            near_wall = cv2.dilate((belief == OCCUPIED).astype(np.uint8), np.ones((m, m), np.uint8)).astype(bool)
            painted &= ~near_wall
        return painted

    def plan(self, observation: Observation) -> list[Waypoint]:
        graph = self.update_graph(observation)
        robot = self.robot_node(observation)
        dist, pred = graph.shortest_paths(robot)
        candidates = self.reachable_useful(robot, dist)
        if candidates.size == 0:
            return []
        belief = observation.belief
        predicted = self.predict()
        gain = graph.utility[candidates].astype(np.float64)
        if predicted.size:
            painted = self.predicted_free_cells(belief, predicted)
            if painted.any():
                free = (belief == FREE) | painted
                gain = gain + visible_counts(free, painted, graph.node_cells[candidates], graph.spec.utility_range / graph.spec.cell_size)
        score = gain / dist[candidates]
        best = int(candidates[np.lexsort((candidates, dist[candidates], -score))[0]])
        self.last_decision = {"target": best, "predicted": int(len(predicted))}
        return self.waypoints_along(graph.path_from_predecessors(pred, best))
