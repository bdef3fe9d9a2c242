"""`guide_tsp`: the GUIDE paper's "w/o diffusion" ablation (Table III).

Every decision: update the lattice graph, predict V_p (Global Node Predictor), build the
region-evaluated global graph (known + kept predicted nodes + centroids, boosted utilities),
cluster the known useful nodes (seeded highest boosted utility first, members within `spread`
metres), order the clusters by an open TSP path from the robot over shortest-path distances
*on the global graph* (so predicted nodes shape the distances and the order), pick the first
target by weight per metre plus tour regret (`GuideTspPlanner` says how), and take one
lattice step toward it along the shortest path on the *known* lattice graph. Re-plan at
every step. Predicted edges only change which target is chosen, never the path driven.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse.csgraph import dijkstra

from pipeline.lattice.tsp import path_length, tsp_path
from pipeline.planners.config import option
from pipeline.planners.graph_planner import GatedPlannerConfig
from pipeline.planners.options import check_int, check_number
from pipeline.planners.predicting import GlobalGraphPlanner, PredictorOptions
from pipeline.planners.registry import register_planner
from pipeline.prediction.global_graph import KNOWN, GlobalGraphConfig
from pipeline.prediction.node_predictor import DEFAULT_COUNT_THRESHOLD, InpaintFn
from pipeline.world.maps import GroundTruthMap
from pipeline.world.planner import Observation, Waypoint
from pipeline.world.protocol import Protocol

# guide_tsp's lengths in node spacings, so that a map drawn at another scale (a 1 m lattice on a
# 0.1 m grid, say) is explored exactly as the 4 m benchmark lattice is: 10 m and 8 m at d_n = 4 m.
SPREAD_NODES = 2.5
HYSTERESIS_NODES = 2.0


@dataclass(frozen=True)
class TourOptions(PredictorOptions, GatedPlannerConfig):
    """The options of guide_tsp's frontier tour over the global graph (also the tour the `guide`
    planners' policy votes on)."""

    count_threshold: float | None = option(DEFAULT_COUNT_THRESHOLD, "tau of the predicted nodes the utility boost "
                                                                    "counts [None: threshold]")
    sliver_gate: bool = option(True, GatedPlannerConfig.__dataclass_fields__["sliver_gate"].metadata["help"])
    top_k: int = option(0, "keep only the heaviest clusters (0 = every cluster)")
    spread: float | None = option(None, f"metres: a useful node this close to a cluster's seed joins it "
                                        f"[default: {SPREAD_NODES:g} node spacings]")
    min_weight: float = option(30.0, "clusters of less summed boosted utility are dropped (the robot clears such "
                                     "slivers on the way; 0 = keep every cluster)")
    beta: float = option(1.5, "weight of the tour regret in a first target's score")
    first_k: int = option(5, "first-target options: the best by weight per metre, and the TSP's own first")
    hysteresis: float | None = option(None, f"metres of tour length the previous first target is forgiven "
                                            f"[default: {HYSTERESIS_NODES:g} node spacings; 0 = none]")
    exact_max: int = option(9, "TSP paths are exact (Held-Karp) up to this many points, else heuristic")
    max_moves: int = option(200, "at most this many 2-opt / Or-opt moves per heuristic TSP path (0 = none)")
    global_graph: GlobalGraphConfig = option(GlobalGraphConfig(), "the global graph's settings (a Python object)")

    def check(self) -> None:
        super().check()
        check_number("count_threshold", self.count_threshold, 0.0, 1.0, none="threshold")
        check_int("top_k", self.top_k, 0, note="0 = every cluster")
        check_number("spread", self.spread, 0.0, low_open=True, none=f"{SPREAD_NODES:g} node spacings")
        check_number("min_weight", self.min_weight, 0.0, note="0 = keep every cluster")
        check_number("beta", self.beta, 0.0)
        check_int("first_k", self.first_k, 1)
        check_number("hysteresis", self.hysteresis, 0.0, note="0 = none", none=f"{HYSTERESIS_NODES:g} node spacings")
        check_int("exact_max", self.exact_max, 1, 14)
        check_int("max_moves", self.max_moves, 0, note="0 = no 2-opt / Or-opt moves")


@dataclass(frozen=True)
class GuideTspConfig(TourOptions):
    description = ("GUIDE w/o diffusion: boosted-utility frontier clusters of the global graph (predicted nodes), "
                   "open TSP over global-graph distances, tour-regret-aware first target, one known-graph step to it")


@register_planner("guide_tsp", GuideTspConfig)
class GuideTspPlanner(GlobalGraphPlanner):
    """GUIDE without the diffusion policy: frontier clusters of the global graph ordered by an open TSP path.

    Every decision: update the lattice graph, predict V_p, build the region-evaluated
    global graph (boosted utilities), then
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
       is forgiven `hysteresis` metres of tour length;
    4. one lattice step toward the first target along the known-graph shortest path.
    Back at a node with nothing new seen since it last decided there, it keeps the target it
    chose there until it gets there or sees something new: replanning on an unchanged map
    can otherwise send it back and forth between two nodes until `max_steps`.

    `spread` and `hysteresis` default to 2.5 and 2 node spacings (10 m and 8 m on the 4 m
    benchmark lattice), so the planner behaves the same on a map drawn at any scale.

    The defaults were tuned on dev mazes, never the test mazes. Predictions only boost
    utilities and shape the tour's distances; a coverage tour planned on the map the predictions
    imply sends the robot on long errands through false free space (docs/findings.md, "guide_tsp").
    """

    base_description = GuideTspConfig.description
    description = base_description

    def __init__(self, config: TourOptions = GuideTspConfig(), inpaint: InpaintFn | None = None):
        super().__init__(config, inpaint)
        top_k, spread, min_weight, beta = config.top_k, config.spread, config.min_weight, config.beta
        first_k, hysteresis, exact_max, max_moves = config.first_k, config.hysteresis, config.exact_max, config.max_moves
        self.top_k = int(top_k)
        self.spread_option, self.hysteresis_option = spread, hysteresis  # metres; None: scaled to d_n in reset()
        self.min_weight = float(min_weight)
        self.beta = float(beta)
        self.first_k = max(1, int(first_k))
        self.exact_max = int(exact_max)
        self.max_moves = int(max_moves)
        self.previous: int | None = None

    def reset(self, ground_truth: GroundTruthMap, protocol: Protocol, seed: int) -> None:
        super().reset(ground_truth, protocol, seed)
        assert self.graph is not None
        d_n = protocol.node_resolution
        self.spread = SPREAD_NODES * d_n if self.spread_option is None else float(self.spread_option)
        self.hysteresis = HYSTERESIS_NODES * d_n if self.hysteresis_option is None else float(self.hysteresis_option)
        self.previous = None
        self.committed: int | None = None  # a first target kept through a cycle (see the class docstring)
        self.quiet_choices: list[tuple[int, int]] = []  # (robot, first target) since the belief last changed

    def select_targets(
        self, candidates: np.ndarray, utility: np.ndarray, dist: np.ndarray, keep: int | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """(cluster targets, cluster weights); `keep` (the previous first target) seeds the first cluster.

        Clusters are seeded highest utility first (nearer on a tie); a candidate within
        `spread` metres of a seed, straight and in path distance from the robot (so a wall
        does not merge two rooms), joins it. Targets are the members nearest the robot
        (`keep` for its own cluster). Clusters under `min_weight` are dropped (unless all are,
        or it is `keep`'s); with `top_k` > 0 only the heaviest `top_k` stay.
        """
        graph = self.graph
        assert graph is not None
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

    def first_target_scores(self, robot: int, dist: np.ndarray, candidates: np.ndarray) -> dict:
        """Cluster the useful nodes, tour them, and score the possible first targets (steps 1-3).

        Needs the global graph already updated for this decision. Returns `targets` and
        `weights` (the clusters), `firsts` (indices into targets of the first-target options),
        `scores` (their weight per metre of distance + beta x tour regret), `tours` (each
        option's tour as lattice ids) and `target_distance` (global-graph distances from every
        target to every global-graph row, for callers that compare other routes to them).
        """
        gg = self.global_graph
        known_ids = gg.lattice_ids[gg.types == KNOWN]  # sorted: the first rows of the global graph
        utility = gg.utility[np.searchsorted(known_ids, candidates)]
        keep = self.previous if self.previous is not None and self.previous in set(candidates.tolist()) else None
        targets, weight = self.select_targets(candidates, utility, dist, keep)
        kept = keep is not None and targets[0] == keep
        points = np.concatenate([[int(np.searchsorted(known_ids, robot))], np.searchsorted(known_ids, targets)])
        rows = dijkstra(gg.adjacency, directed=False, indices=points)
        d = rows[:, points]
        d = np.minimum(d, d.T)
        if not np.isfinite(d).all():  # cannot happen (known edges are in the global graph); be safe
            d = np.where(np.isfinite(d), d, 1e6)
        order, length = self._tour(d)
        options: dict[int, tuple[float, list[int]]] = {order[1]: (np.inf, order)}
        if len(targets) > 1:
            per_metre = weight / np.maximum(d[0, 1:], 1e-6)
            firsts = set((np.argsort(-per_metre, kind="stable")[: self.first_k] + 1).tolist()) | {order[1]}
            if kept:
                firsts.add(1)
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
            "target_distance": rows[1:],
        }

    def plan(self, observation: Observation) -> list[Waypoint]:
        graph, robot, dist, pred, candidates = self.locate(observation)
        if candidates.size == 0:
            return []
        predicted = self.update_global_graph(observation)
        options = self.first_target_scores(robot, dist, candidates)
        best = int(np.argmax(options["scores"]))  # the first option wins a tie (lowest target index)
        tour = options["tours"][best]
        first = self.keep_through_cycles(observation, robot, candidates, tour[0])
        if first != tour[0]:
            tour = [first] + [t for t in tour if t != first]
        self.previous = first
        self.last_decision = {
            "targets": options["targets"],
            "weights": options["weights"],
            "tour": tour,
            "length": options["length"],
            "predicted": int(len(predicted)),
        }
        return self.waypoints_along(graph.path_from_predecessors(pred, first))

    def keep_through_cycles(self, observation: Observation, robot: int, candidates: np.ndarray, first: int) -> int:
        """The first target to head for: `first`, unless the robot is back at a node with nothing
        new seen since it decided there; then the target it chose there, kept until reached or news."""
        if observation.changed is None or len(observation.changed) > 0:
            self.quiet_choices, self.committed = [], None
        useful = set(candidates.tolist())
        if self.committed is not None and (self.committed == robot or self.committed not in useful):
            self.committed = None
        if self.committed is None:
            earlier = [target for node, target in self.quiet_choices if node == robot and target != robot and target in useful]
            if earlier:
                self.committed = earlier[0]
        chosen = first if self.committed is None else self.committed
        self.quiet_choices.append((robot, chosen))
        return chosen
