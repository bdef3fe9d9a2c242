"""Planners, each registered under a lower-case name (`guide planners` lists them)."""

from pipeline.planners.baselines import frontier, mapex, nbvp, tare  # noqa: F401  (register their planners)
from pipeline.planners.extensions import sampled_lookahead  # noqa: F401
from pipeline.planners.guide import guide, guide_tsp  # noqa: F401
from pipeline.planners.references import coverage_planners, oracle_bounds  # noqa: F401
from pipeline.planners.registry import make_planner, planner_class, planner_names, register_planner
from pipeline.world.planner import Planner

__all__ = ["Planner", "make_planner", "planner_class", "planner_names", "register_planner"]
