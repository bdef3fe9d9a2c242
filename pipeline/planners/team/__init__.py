"""Team planners: one decision for one robot of a team at a time (`pipeline.world.team`).

- `registry`: team names and `make_team_planner`; a single-robot name without a team version
  runs uncoordinated;
- `uncoordinated`: every robot runs its own single-robot planner on its belief, blind to the others.
"""
