"""Planners, each registered under a lower-case name (`guide planners` lists them)."""

from pipeline.planners import frontier  # noqa: F401  (registers nearest_frontier, greedy_utility)
from pipeline.planners import nbvp  # noqa: F401
from pipeline.planners import coverage  # noqa: F401
from pipeline.planners import tare  # noqa: F401
from pipeline.planners import global_graph_planners  # noqa: F401
from pipeline.planners import guide  # noqa: F401  (registers guide, guide_noregion, dare)
from pipeline.planners import oracle_bounds  # noqa: F401  (registers oracle_gate, oracle_tail)
from pipeline.planners import sampled_lookahead  # noqa: F401
from pipeline.planners.base import Planner, make_planner, planner_class, planner_names, register_planner

__all__ = ["Planner", "make_planner", "planner_class", "planner_names", "register_planner"]
