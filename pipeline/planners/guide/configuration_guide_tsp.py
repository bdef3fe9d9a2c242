"""The options of `guide_tsp`, the paper's "w/o diffusion" ablation: a frontier tour over the
global graph (`FrontierTour` in `guide_tsp.py`). Our tour vote scores the same tour's first
targets, so its config takes these options too."""

from __future__ import annotations

from typing import Annotated

from pipeline.common.config import config_dataclass, flag, maybe, real, whole
from pipeline.planners.config import option
from pipeline.planners.graph_planner import GatedPlannerConfig
from pipeline.planners.predicting import GlobalGraphOptions

# guide_tsp's lengths in node spacings, so that a map drawn at another scale (a 1 m lattice on a
# 0.1 m grid, say) is explored exactly as the 4 m benchmark lattice is: 10 m and 8 m at d_n = 4 m.
SPREAD_NODES = 2.5
HYSTERESIS_NODES = 2.0


@config_dataclass
class TourOptions(GlobalGraphOptions, GatedPlannerConfig):
    """The frontier tour over the global graph: how useful nodes cluster, how the tour is solved,
    how its first target is scored."""

    part = "the frontier tour (ours)"

    sliver_gate: Annotated[bool, flag()] = option(
        True, GatedPlannerConfig.__dataclass_fields__["sliver_gate"].metadata["help"]
    )
    top_k: Annotated[int, whole(0, note="0 = every cluster")] = option(
        0, "keep only the heaviest clusters (0 = every cluster)"
    )
    spread: Annotated[
        float | None, maybe(real(0.0, note="0 = each useful node its own target"), f"{SPREAD_NODES:g} node spacings")
    ] = option(
        None,
        f"metres: a useful node this close to a cluster's seed joins it [default: {SPREAD_NODES:g} node spacings; "
        "0 = each useful node its own target]",
    )
    min_weight: Annotated[float, real(0.0, note="0 = keep every cluster")] = option(
        30.0,
        "clusters of less summed boosted utility are dropped (the robot clears such slivers on the way; "
        "0 = keep every cluster)",
    )
    beta: Annotated[float, real(0.0)] = option(1.5, "weight of the tour regret in a first target's score")
    first_k: Annotated[int, whole(1)] = option(
        5, "first-target options: the best by weight per metre, and the TSP's own first"
    )
    hysteresis: Annotated[float | None, maybe(real(0.0, note="0 = none"), f"{HYSTERESIS_NODES:g} node spacings")] = (
        option(
            None,
            f"metres of tour length the previous first target is forgiven, through the regret (none at beta 0) "
            f"[default: {HYSTERESIS_NODES:g} node spacings; 0 = none]",
        )
    )
    exact_max: Annotated[int, whole(1, 14)] = option(
        9, "TSP paths are exact (Held-Karp) up to this many points, else heuristic"
    )
    max_moves: Annotated[int, whole(0, note="0 = no 2-opt / Or-opt moves")] = option(
        200, "at most this many 2-opt / Or-opt moves per heuristic TSP path (0 = none)"
    )


@config_dataclass
class GuideTspConfig(TourOptions):
    description = (
        "GUIDE w/o diffusion: boosted-utility frontier clusters of the global graph (predicted nodes), "
        "open TSP over global-graph distances, tour-regret-aware first target, one known-graph step to it"
    )
