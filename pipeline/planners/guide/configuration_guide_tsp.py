"""The options of `guide_tsp`, the paper's "w/o diffusion" ablation: a frontier tour over the
global graph (`FrontierTour` in `guide_tsp.py`). Our tour vote scores the same tour's first
targets, so its config takes these options too."""

from __future__ import annotations

from dataclasses import dataclass

from pipeline.planners.config import option
from pipeline.planners.graph_planner import GatedPlannerConfig
from pipeline.planners.options import check_int, check_number
from pipeline.planners.predicting import GlobalGraphOptions

# guide_tsp's lengths in node spacings, so that a map drawn at another scale (a 1 m lattice on a
# 0.1 m grid, say) is explored exactly as the 4 m benchmark lattice is: 10 m and 8 m at d_n = 4 m.
SPREAD_NODES = 2.5
HYSTERESIS_NODES = 2.0


@dataclass(frozen=True)
class TourOptions(GlobalGraphOptions, GatedPlannerConfig):
    """The frontier tour over the global graph: how useful nodes cluster, how the tour is solved,
    how its first target is scored."""

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

    def check(self) -> None:
        super().check()
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
