"""Every planner on lattices one or two nodes across (a corridor wing): no crash, the corridor explored."""

from dataclasses import replace

import numpy as np
import pytest

from pipeline.planners import make_planner, planner_names
from pipeline.world.maps import GroundTruthMap
from pipeline.world.protocol import PAPER_REAL_ROBOT
from pipeline.world.simulator import run_episode

PROTOCOL = replace(PAPER_REAL_ROBOT, done_unknown_cells=5, max_steps=200)


def corridor(rows: int, cols: int) -> GroundTruthMap:
    """A free corridor of rows x cols cells of 0.2 m (the 1 m lattice: one node every 5 cells)."""
    start = (min(2, cols // 2), min(2, rows // 2))
    return GroundTruthMap(
        free=np.ones((rows, cols), bool), start_cell=start, cell_size=0.2, name=f"corridor_{rows}x{cols}"
    )


@pytest.mark.parametrize("shape", [(3, 120), (7, 120), (120, 3)], ids=["one_row", "two_rows", "one_column"])
@pytest.mark.parametrize("name", planner_names())
def test_every_planner_explores_a_corridor_one_or_two_nodes_across(name, shape):
    world = corridor(*shape)
    result = run_episode(world, make_planner(name), PROTOCOL)
    assert result.complete and result.motion_violations == 0, result.failure
