"""Team planners: one decision for one robot of a team at a time (`pipeline.world.team`).

- `registry`: team names and `make_team_planner`; a single-robot name without a team version
  runs uncoordinated;
- `uncoordinated`: every robot runs its own single-robot planner on its belief, blind to the others;
- `coordinated_greedy`: `greedy_utility` with Burgard et al.'s utility reduction near teammates' goals;
- `coordinated_tour`: `guide_tsp` and `guide` with the global graph's frontier split into min-max
  routes for the team (`min_max_routes`), each robot heading along its own;
- `heard_goals`: what each robot knows of its teammates' goals, passed on the episode's links;
- `team_optimal`: the ground-truth team reference `optimal`: covering viewpoints split into
  min-max routes on the true map.
"""

from pipeline.planners.team import (
    coordinated_greedy,  # noqa: F401  (registers the team greedy_utility)
    coordinated_tour,  # noqa: F401  (registers the team guide_tsp and guide)
    team_optimal,  # noqa: F401  (registers the team optimal reference)
)
