"""`mapex`: after MapEx (Ho et al., 2024), information gain on the predicted map.

Candidate viewpoints are the useful nodes (unvisited known free nodes that see frontier).
The predicted map is the belief with a disc of radius node_resolution / 2 painted free around
every predicted node (unknown cells only). A candidate's gain counts the unknown cells that
its ray fan (the graph utility's fan, `utility_range`) reaches through belief-free or
predicted-free cells and that are predicted free (minus cells within `wall_margin` cells of a
known obstacle: the inside of a wall whose face was seen is never observed, and counting it
made the robot come back for it), plus its frontier utility on the observed map (what it
would see anyway, so that with no prediction `mapex` is `greedy_utility`). Score = gain /
path cost on the known graph; one lattice step toward the best. MapEx weights its gain by
the variance of an ensemble of predictors; we have a single predictor and no variance, so
the gain is unweighted.
"""

from __future__ import annotations

from typing import Annotated

import cv2
import numpy as np

from pipeline.common.config import config_dataclass, fraction, whole
from pipeline.lattice.visibility import visible_counts
from pipeline.planners.config import option
from pipeline.planners.predicting import PredictingPlanner, PredictorOptions
from pipeline.prediction.node_predictor import DEFAULT_COUNT_THRESHOLD, InpaintFn
from pipeline.world.planner import Observation, Waypoint
from pipeline.world.sensor import FREE, OCCUPIED, UNKNOWN


@config_dataclass
class MapExConfig(PredictorOptions):
    description = (
        "MapEx (Ho 2024): frontier viewpoints scored by gain on the predicted map (predicted-free "
        "unknown cells in the ray fan, unweighted: no ensemble variance) over path cost"
    )

    # Its predicted map is a count of likely-free space, not graph nodes: the utility count's tau.
    threshold: Annotated[float, fraction()] = option(
        DEFAULT_COUNT_THRESHOLD,
        "tau: an unknown node is predicted free at P(free) >= "
        "tau (the broad tau of the utility count, not the graph's)",
    )
    wall_margin: Annotated[int, whole(0, note="0 = off")] = option(
        2,
        "cells: predicted-free unknown this close to a known obstacle is "
        "the inside of a seen wall, not counted (0 = off)",
    )


class MapExPlanner(PredictingPlanner):
    """MapEx-style: information gain on the predicted map per metre of path, best viewpoint first."""

    base_description = MapExConfig.description
    description = base_description

    def __init__(self, config: MapExConfig = MapExConfig(), inpaint: InpaintFn | None = None):
        super().__init__(config, inpaint)
        wall_margin = config.wall_margin
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
        graph, robot, dist, pred, candidates = self.locate(observation)
        if candidates.size == 0:
            return []
        belief = observation.belief
        predicted = self.predict()
        gain = graph.utility[candidates].astype(np.float64)
        if predicted.size:
            painted = self.predicted_free_cells(belief, predicted)
            if painted.any():
                free = (belief == FREE) | painted
                gain = gain + visible_counts(
                    free, painted, graph.node_cells[candidates], graph.spec.utility_range / graph.spec.cell_size
                )
        score = gain / dist[candidates]
        best = int(candidates[np.lexsort((candidates, dist[candidates], -score))[0]])
        self.last_decision = {"target": best, "predicted": int(len(predicted))}
        return self.waypoints_along(graph.path_from_predecessors(pred, best))
