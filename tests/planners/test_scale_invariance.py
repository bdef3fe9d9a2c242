"""Every exploring planner explores a map drawn at another scale exactly as the benchmark's.

The same maze PNG read at 0.1 m per cell, with a 1 m lattice, 5 m sensor, 2.5 m utility
range and 5 m regions, is the 0.4 m / 4 m / 20 m benchmark world shrunk by four: every
cell-level quantity is unchanged. A planner whose lengths are tied to the lattice (not to
metres) must then take the same waypoints, and travel exactly a quarter of the distance.
Scaling by a power of two is exact in floating point, so the check can be strict.
"""

from __future__ import annotations

import pytest

from pipeline.models.defaults import SHIPPED_INPAINTER, SHIPPED_POLICY
from pipeline.planners import make_planner
from pipeline.world.maps import load_maze_png
from pipeline.world.protocol import Protocol
from pipeline.world.simulator import run_episode
from tests.conftest import SINGLE_NODES

BENCHMARK = Protocol()
# DARE's lattice at a quarter scale too: a 1 m lattice would otherwise take the door-aware graph,
# which passes gaps the full-scale lattice does not (a scaled maze has none to pass).
QUARTER = Protocol(
    cell_size=0.1, node_resolution=1.0, sensor_range=5.0, utility_range=2.5, region_size=5.0, door_graph=False
)
INPAINTER = str(SHIPPED_INPAINTER)
# The targets guide's policy votes on are set: their defaults depend on the scale a protocol names
# (`pipeline.planners.protocol_defaults`), and this check is of the mechanics, not of the defaults.
TARGETS = SINGLE_NODES

PLANNERS = {
    "nearest_frontier": {},
    "greedy_utility": {},
    "tare": {},
    "nbvp": {},
    "guide_tsp": {"inpainter_file": INPAINTER},
    "mapex": {"inpainter_file": INPAINTER},
    # Two denoising steps: scale invariance does not depend on K, and K = 30 triples the test's time.
    "guide": {
        "policy_file": str(SHIPPED_POLICY["guide"]),
        "inpainter_file": INPAINTER,
        "num_inference_steps": 2,
        **TARGETS,
    },
    "guide_noregion": {
        "policy_file": str(SHIPPED_POLICY["guide"]),
        "inpainter_file": INPAINTER,
        "num_inference_steps": 2,
        **TARGETS,
    },
    "dare": {"policy_file": str(SHIPPED_POLICY["dare"]), "num_inference_steps": 2, **TARGETS},
}


# The learned planners' models were trained at the full-scale protocol: at a quarter scale they say so.
@pytest.mark.filterwarnings("ignore::pipeline.world.protocol.ProtocolMismatchWarning")
@pytest.mark.parametrize("name", sorted(PLANNERS))
def test_a_quarter_scale_map_is_explored_on_the_same_waypoints(name, small_maze_path):
    runs = []
    for protocol in (BENCHMARK, QUARTER):
        ground_truth = load_maze_png(small_maze_path, cell_size=protocol.cell_size)
        result = run_episode(ground_truth, make_planner(name, **PLANNERS[name]), protocol, seed=0)
        runs.append(result)
    full, quarter = runs
    assert full.complete and quarter.complete
    assert quarter.steps == full.steps
    assert quarter.distance_m * 4 == pytest.approx(full.distance_m, rel=1e-12)
