"""`guide_tsp`: the GUIDE paper's "w/o diffusion" ablation (Table III).

Every decision: update the lattice graph, predict V_p (Global Node Predictor), build the
region-evaluated global graph (known + kept predicted nodes + centroids, boosted utilities),
then tour its frontier (`FrontierTour`): cluster the known useful nodes (seeded highest boosted
utility first, members within `spread` metres), order the clusters by an open TSP path from the
robot over shortest-path distances *on the global graph* (so predicted nodes shape the distances
and the order), pick the first target by weight per metre plus tour regret, and take one lattice
step toward it along the shortest path on the *known* lattice graph. Re-plan at every step.
Predicted edges only change which target is chosen, never the path driven. Our tour vote
(`pipeline.planners.extensions.tour_vote`) lets GUIDE's policy vote on the same tour.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse.csgraph import dijkstra

from pipeline.lattice.graph import LatticeGraph
from pipeline.lattice.tsp import path_length, tsp_path
from pipeline.planners.guide.configuration_guide_tsp import HYSTERESIS_NODES, SPREAD_NODES, GuideTspConfig, TourOptions
from pipeline.planners.predicting import GlobalGraphPlanner
from pipeline.prediction.global_graph import KNOWN, GlobalGraph
from pipeline.prediction.node_predictor import InpaintFn
from pipeline.world.maps import MapFrame
from pipeline.world.planner import Observation, Waypoint
from pipeline.world.protocol import Protocol


class FrontierTour:
    """guide_tsp's tour over the global graph's frontier, and its cycle guard.

    1. cluster *all* reachable useful known nodes: highest boosted utility first, a node
       within `spread` metres of a cluster's seed (straight line and path distance from the
       robot) joins it; a cluster's weight is its summed boosted utility and its target is
       its member nearest the robot along the known graph. Clusters lighter than
       `min_weight` are dropped (the robot clears such frontier slivers on the way);
    2. shortest-path distances between robot and targets on the global graph (predicted
       nodes shape them) and an open TSP path from the robot (`tsp_path`: exact when small);
    3. the first target: among the `first_k` best by weight per metre plus the TSP's own
       first, the one with the most weight per metre of (its distance + `beta` x how much
       longer the best tour starting there is than the best tour); the rest of the tour is
       the TSP order after it. Hysteresis: the previous first target, while still useful,
       is forgiven `hysteresis` metres of tour length.
    Back at a node with nothing new seen since it last decided there, it keeps the target it
    chose there until it gets there or sees something new (`keep_through_cycles`): replanning
    on an unchanged map can otherwise send it back and forth between two nodes until `max_steps`.

    `spread` and `hysteresis` default to 2.5 and 2 node spacings (10 m and 8 m on the 4 m
    benchmark lattice), so the tour is the same on a map drawn at any scale.
    """

    def __init__(self, config: TourOptions):
        self.top_k = int(config.top_k)
        self.spread_option, self.hysteresis_option = config.spread, config.hysteresis  # metres; None: scaled in reset()
        self.min_weight = float(config.min_weight)
        self.beta = float(config.beta)
        self.first_k = max(1, int(config.first_k))
        self.exact_max = int(config.exact_max)
        self.max_moves = int(config.max_moves)
        self.previous: int | None = None

    def reset(self, protocol: Protocol) -> None:
        d_n = protocol.node_resolution
        self.spread = SPREAD_NODES * d_n if self.spread_option is None else float(self.spread_option)
        self.hysteresis = HYSTERESIS_NODES * d_n if self.hysteresis_option is None else float(self.hysteresis_option)
        self.previous = None  # the last first target
        self.committed: int | None = None  # a first target kept through a cycle (see the class docstring)
        self.quiet_choices: list[tuple[int, int]] = []  # (robot, first target) since the belief last changed

    def select_targets(
        self,
        graph: LatticeGraph,
        candidates: np.ndarray,
        utility: np.ndarray,
        dist: np.ndarray,
        keep: int | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """(cluster targets, cluster weights); `keep` (the previous first target) seeds the first cluster.

        Clusters are seeded highest utility first (nearer on a tie); a candidate within
        `spread` metres of a seed, straight and in path distance from the robot (so a wall
        does not merge two rooms), joins it. Targets are the members nearest the robot
        (`keep` for its own cluster). Clusters under `min_weight` are dropped (unless all are,
        or it is `keep`'s); with `top_k` > 0 only the heaviest `top_k` stay.
        """
        order = np.lexsort((candidates, dist[candidates], -utility))
        if keep is not None:
            where = np.nonzero(candidates[order] == keep)[0]
            if where.size:
                order = np.concatenate([order[where], np.delete(order, where)])
        kept = keep is not None and candidates[order[0]] == keep
        xy = graph.node_world[candidates]
        d_robot = dist[candidates]
        seeds: list[int] = []  # indices into candidates
        members: list[list[int]] = []
        weight: list[float] = []
        for k in order:
            if seeds:
                s = np.asarray(seeds)
                near = (np.hypot(*(xy[s] - xy[k]).T) < self.spread) & (np.abs(d_robot[s] - d_robot[k]) < self.spread)
                if near.any():
                    j = int(np.nonzero(near)[0][0])
                    weight[j] += float(utility[k])
                    members[j].append(int(k))
                    continue
            seeds.append(int(k))
            members.append([int(k)])
            weight.append(float(utility[k]))
        picks = [m[0] if (kept and j == 0) else m[int(np.argmin(d_robot[m]))] for j, m in enumerate(members)]
        targets = candidates[np.asarray(picks, dtype=np.int64)]
        weights = np.asarray(weight)
        mask = weights >= self.min_weight
        if kept:
            mask[0] = True
        if not mask.any():
            mask[:] = True
        targets, weights = targets[mask], weights[mask]
        if self.top_k and targets.size > self.top_k:
            top = np.argsort(-weights, kind="stable")[: self.top_k]
            if kept and 0 not in top:
                top[-1] = 0
            top = np.sort(top)
            targets, weights = targets[top], weights[top]
        return targets, weights

    def _tour(self, d: np.ndarray, first: int | None = None) -> tuple[list[int], float]:
        """Open TSP path over `d` from point 0 (through `first` next when given); (order, length)."""
        if first is None:
            order = tsp_path(d, None, self.exact_max, self.max_moves)
        else:
            rest = [i for i in range(len(d)) if i not in (0, first)]
            tail = tsp_path(d[np.ix_([first] + rest, [first] + rest)], None, self.exact_max, self.max_moves)
            order = [0, first] + [rest[i - 1] for i in tail[1:]]
        return order, path_length(d, order)

    def first_target_scores(
        self, graph: LatticeGraph, global_graph: GlobalGraph, robot: int, dist: np.ndarray, candidates: np.ndarray
    ) -> dict:
        """Cluster the useful nodes, tour them, and score the possible first targets (steps 1-3).

        `global_graph` must be updated for this decision. Returns `targets` and
        `weights` (the clusters), `firsts` (indices into targets of the first-target options),
        `scores` (their weight per metre of distance + beta x tour regret), `tours` (each
        option's tour as lattice ids), `length` (the tour's) and `option_distance` (global-graph
        distances from each option's target to every global-graph row, for callers that
        compare other routes to them).

        With no regret (`beta` 0) and a nearest-neighbour tour without moves (`max_moves` 0,
        more targets than `exact_max`), the tour's first target is the nearest and its rest
        changes no score: only the distances from the robot and from the options are computed,
        each option's tour is its target alone and `length` is None (`first_target_options`).
        """
        gg = global_graph
        known_ids = gg.lattice_ids[gg.types == KNOWN]  # sorted: the first rows of the global graph
        utility = gg.utility[np.searchsorted(known_ids, candidates)]
        keep = self.previous if self.previous is not None and self.previous in set(candidates.tolist()) else None
        targets, weight = self.select_targets(graph, candidates, utility, dist, keep)
        kept = keep is not None and targets[0] == keep
        points = np.concatenate([[int(np.searchsorted(known_ids, robot))], np.searchsorted(known_ids, targets)])
        if not self.tour_scores(len(points)):
            return self.first_target_options(gg, points, targets, weight, kept)
        rows = dijkstra(gg.adjacency, directed=False, indices=points)
        d = rows[:, points]
        d = np.minimum(d, d.T)
        if not np.isfinite(d).all():  # cannot happen (known edges are in the global graph); be safe
            d = np.where(np.isfinite(d), d, 1e6)
        order, length = self._tour(d)
        options: dict[int, tuple[float, list[int]]] = {order[1]: (np.inf, order)}
        if len(targets) > 1:
            firsts = self._options(weight, d[0, 1:], order[1], kept)
            options = {}
            for j in sorted(firsts):
                o_j, l_j = (order, length) if j == order[1] else self._tour(d, j)
                slack = self.hysteresis if kept and j == 1 else 0.0
                options[j] = (weight[j - 1] / (d[0, j] + self.beta * max(0.0, l_j - length - slack) + 1e-6), o_j)
        firsts = sorted(options)
        return {
            "targets": targets,
            "weights": weight,
            "firsts": np.asarray([j - 1 for j in firsts], dtype=np.int64),
            "scores": np.asarray([options[j][0] for j in firsts]),
            "tours": [[int(targets[k - 1]) for k in options[j][1][1:]] for j in firsts],
            "length": length,
            "option_distance": rows[1:][[j - 1 for j in firsts]],
        }

    def _options(self, weight: np.ndarray, distance: np.ndarray, tour_first: int, kept: bool) -> list[int]:
        """The first-target options (1-based target indices, ascending): the `first_k` best by
        weight per metre of `distance` from the robot, the tour's own first, and the kept target."""
        firsts = set((np.argsort(-(weight / np.maximum(distance, 1e-6)), kind="stable")[: self.first_k] + 1).tolist())
        return sorted(firsts | {tour_first} | ({1} if kept else set()))

    def tour_scores(self, points: int) -> bool:
        """Whether the tour beyond its first target changes a score among `points` (the robot's
        and the targets'): through the regret (`beta`), or through the first target of an exact
        or improved tour, which need not be the nearest."""
        nearest_neighbour = points <= 2 or (points > self.exact_max and self.max_moves == 0)
        return self.beta != 0 or not nearest_neighbour

    def first_target_options(
        self, gg: GlobalGraph, points: np.ndarray, targets: np.ndarray, weight: np.ndarray, kept: bool
    ) -> dict:
        """`first_target_scores` without a tour: each option scored by its weight per metre of
        distance from the robot (global-graph rows `points`: the robot's, then the targets')."""
        from_robot = dijkstra(gg.adjacency, directed=False, indices=points[:1])[0, points]
        from_robot = np.where(np.isfinite(from_robot), from_robot, 1e6)
        nearest = 1 + int(np.argmin(from_robot[1:]))  # the nearest-neighbour tour's first (lowest index on a tie)
        firsts = self._options(weight, from_robot[1:], nearest, kept) if len(targets) > 1 else [nearest]
        rows = dijkstra(gg.adjacency, directed=False, indices=points[firsts])
        distance = np.minimum(from_robot[firsts], rows[:, points[0]])  # symmetric, as the tour's matrix
        distance = np.where(np.isfinite(distance), distance, 1e6)
        scores = weight[np.asarray(firsts) - 1] / (distance + 1e-6) if len(targets) > 1 else np.array([np.inf])
        return {
            "targets": targets,
            "weights": weight,
            "firsts": np.asarray([j - 1 for j in firsts], dtype=np.int64),
            "scores": scores,
            "tours": [[int(targets[j - 1])] for j in firsts],
            "length": None,
            "option_distance": rows,
        }

    def keep_through_cycles(self, observation: Observation, robot: int, candidates: np.ndarray, first: int) -> int:
        """The first target to head for: `first`, unless the robot is back at a node with nothing
        new seen since it decided there; then the target it chose there, kept until reached or news."""
        if observation.changed is None or len(observation.changed) > 0:
            self.quiet_choices, self.committed = [], None
        useful = set(candidates.tolist())
        if self.committed is not None and (self.committed == robot or self.committed not in useful):
            self.committed = None
        if self.committed is None:
            earlier = [
                target for node, target in self.quiet_choices if node == robot and target != robot and target in useful
            ]
            if earlier:
                self.committed = earlier[0]
        chosen = first if self.committed is None else self.committed
        self.quiet_choices.append((robot, chosen))
        return chosen


class GuideTspPlanner(GlobalGraphPlanner):
    """GUIDE without the diffusion policy: the global graph's frontier tour (`FrontierTour`), one
    known-graph step toward its first target at every decision.

    The defaults were tuned on dev mazes, never the test mazes. Predictions only boost
    utilities and shape the tour's distances; a coverage tour planned on the map the predictions
    imply sends the robot on long errands through false free space.
    """

    base_description = GuideTspConfig.description
    description = base_description

    def __init__(self, config: TourOptions = GuideTspConfig(), inpaint: InpaintFn | None = None):
        super().__init__(config, inpaint)
        self.tour = FrontierTour(config)

    def reset(self, frame: MapFrame, protocol: Protocol, seed: int) -> None:
        super().reset(frame, protocol, seed)
        self.tour.reset(protocol)

    def plan(self, observation: Observation) -> list[Waypoint]:
        graph, robot, dist, pred, candidates = self.locate(observation)
        if candidates.size == 0:
            return []
        predicted = self.update_global_graph(observation)
        options = self.tour.first_target_scores(graph, self.global_graph, robot, dist, candidates)
        best = int(np.argmax(options["scores"]))  # the first option wins a tie (lowest target index)
        tour = options["tours"][best]
        first = self.tour.keep_through_cycles(observation, robot, candidates, tour[0])
        if first != tour[0]:
            tour = [first] + [t for t in tour if t != first]
        self.tour.previous = first
        self.last_decision = {
            "targets": options["targets"],
            "weights": options["weights"],
            "tour": tour,
            "length": options["length"],
            "predicted": int(len(predicted)),
        }
        return self.waypoints_along(graph.path_from_predecessors(pred, first))
