"""Planners, each registered under a lower-case name with its config (`guide planners` lists them).

- `baselines/`: nearest frontier, greedy utility, NBVP, TARE, MapEx, DRL;
- `guide/`: the paper's planner (`GuidePlanner`, Sec. IV-C) and its "w/o diffusion" ablation `guide_tsp`;
- `extensions/`: what we added beyond the paper, each wrapping what it changes (ranked plans,
  stall hand-over, tour vote, block-model lookahead);
- `catalog`: the registered `guide`, `guide_noregion`, `dare`, `guide_tsp` and `mapex`, with our
  additions around them (the tour vote, trust in predictions);
- `references/`: the ground-truth `optimal` and `expert`, and the oracle bounds.
"""

from pipeline.planners import catalog  # noqa: F401  (registers guide, guide_noregion, dare, guide_tsp, mapex)
from pipeline.planners.baselines import drl, frontier, mapex, nbvp, tare  # noqa: F401  (register their planners)
from pipeline.planners.extensions import sampled_lookahead  # noqa: F401
from pipeline.planners.guide import guide_tsp  # noqa: F401
from pipeline.planners.references import coverage_planners, oracle_bounds  # noqa: F401
from pipeline.planners.registry import make_planner, planner_config, planner_names, register_planner
from pipeline.world.planner import Planner

__all__ = ["Planner", "make_planner", "planner_config", "planner_names", "register_planner"]
