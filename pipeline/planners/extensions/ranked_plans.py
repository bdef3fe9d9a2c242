"""Several sampled plans, ranked by frontier per metre (ours, not the paper's).

The paper drives the policy's one sample. With `candidates` > 1 the policy draws that many
plans in one batched call, and the one that sees the most new frontier per metre when driven on
the known graph is executed (`rank_plans`). A single sample of a policy trained on few episodes
often heads into explored space; ranking several hides most of that.
"""

from __future__ import annotations

from typing import Annotated

import numpy as np
from scipy.sparse.csgraph import dijkstra

from pipeline.common.config import config_dataclass, whole
from pipeline.planners.config import PlannerConfig, option
from pipeline.planners.guide.guide import GuidePlanner, drive
from pipeline.prediction.global_graph import KNOWN

LATER_STEP_WEIGHT = 0.8  # a plan's k-th step counts 0.8^k of its utility: near gains are surer


@config_dataclass
class SampledPlansConfig(PlannerConfig):
    """How many plans the policy samples per decision (the ranked plans and the tour vote read it)."""

    part = "sampled plans (ours)"

    candidates: Annotated[int, whole(1)] = option(
        8, "plans sampled per decision, in one batched pass (mode policy, 1: the paper's single sample)"
    )


def rank_plans(paper: GuidePlanner, deltas: np.ndarray, expected: np.ndarray) -> int:
    """Index of the sampled plan that sees the most new frontier per metre when driven on the known graph.

    Each candidate's T_p steps are mapped to feasible moves as they would be executed; its
    score is the global graph's utility u(v) (frontier utility boosted by the predicted nodes
    in range; plain frontier utility for `dare`) of the distinct unvisited nodes it reaches,
    with each later step weighted less, over its length. Plans that reach no frontier are
    ordered by how close they end to the nearest useful node (shortest path on the known
    graph), so that in explored space the proposal that heads toward unexplored space wins.
    Ties keep the first sample.
    """
    graph, robot = paper.graph, paper.robot
    assert graph is not None
    useful = paper.useful_nodes()
    to_useful = (
        dijkstra(graph.adjacency(), directed=False, indices=useful, min_only=True)
        if useful.size
        else np.zeros(graph.node_count)
    )
    utility = np.zeros(graph.node_count)  # u(v) of the global graph's known nodes (Sec. IV-B.3)
    gg = paper.global_graph
    known = gg.types == KNOWN
    utility[gg.lattice_ids[known]] = gg.utility[known]
    scores = np.zeros(len(deltas))
    scale = graph.spec.node_resolution / 4.0  # lengths in metres of the 4 m benchmark lattice, at any scale
    for c, path in enumerate(drive(graph, robot, deltas, expected)):
        seen, gain, length = set(), 0.0, 0.0
        for k, (node, nxt) in enumerate(zip(path[:-1], path[1:])):
            length += float(np.hypot(*(graph.node_world[nxt] - graph.node_world[node])))
            if nxt not in seen and not paper.visited[nxt]:
                gain += (LATER_STEP_WEIGHT**k) * float(utility[nxt])
            seen.add(nxt)
        end = path[-1]
        remaining = float(to_useful[end]) if np.isfinite(to_useful[end]) else 1e6
        scores[c] = gain / (length / scale + 1.0) - 1e-6 * remaining / scale
    return int(np.argmax(scores))
