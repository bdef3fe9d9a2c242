"""Door nodes: edges valid through a gap in a wall that no straight lattice edge crosses."""

from dataclasses import replace

import numpy as np
from conftest import two_rooms

from pipeline.lattice.doors import find_door_node, via_waypoints
from pipeline.lattice.graph import LatticeGraph
from pipeline.lattice.spec import LatticeSpec
from pipeline.world.geometry import segment_is_known_free
from pipeline.world.maps import GroundTruthMap
from pipeline.world.protocol import PAPER_REAL_ROBOT, Protocol
from pipeline.world.reachability import clearance_cells
from pipeline.world.sensor import FREE, OCCUPIED


def known(ground_truth: GroundTruthMap) -> np.ndarray:
    return np.where(ground_truth.free, FREE, OCCUPIED).astype(np.uint8)


def reached_nodes(ground_truth: GroundTruthMap, protocol: Protocol) -> tuple[LatticeGraph, np.ndarray]:
    graph = LatticeGraph(LatticeSpec.for_map(ground_truth, protocol))
    graph.update(known(ground_truth))
    return graph, np.isfinite(graph.shortest_paths(graph.nearest_node((0.0, 0.0)))[0])


def test_the_door_graph_joins_rooms_that_the_lattice_leaves_apart():
    world = two_rooms()
    lattice, reached_lattice = reached_nodes(world, replace(PAPER_REAL_ROBOT, door_graph=False))
    doors, reached_doors = reached_nodes(world, PAPER_REAL_ROBOT)
    right_room = lattice.node_cells[:, 0] > 27
    assert not reached_lattice[right_room].any()
    assert reached_doors[right_room & (doors.node_state == 1)].all()
    via = np.flatnonzero(doors.edge_via >= 0)
    assert via.size and (doors.edge_cost[via] >= doors.edge_length[via]).all()
    cols = world.shape[1]
    door_cells = {(int(f % cols), int(f // cols)) for f in doors.edge_via[via]}
    assert all(world.free[row, col] for col, row in door_cells)
    # Each half of every edge through a door node is a known-free walk.
    free = world.free
    for e in via:
        a, b = (tuple(doors.node_cells[n]) for n in doors.edge_nodes[e])
        door = (int(doors.edge_via[e] % cols), int(doors.edge_via[e] // cols))
        assert segment_is_known_free(free, a, door) and segment_is_known_free(free, door, b)


def test_the_maze_protocol_keeps_dares_lattice():
    world = two_rooms()
    graph, _ = reached_nodes(world, replace(PAPER_REAL_ROBOT, node_resolution=4.0, cell_size=0.2))
    assert not Protocol().uses_door_graph and graph.spec.door_radius_cells is None
    assert (graph.edge_via < 0).all() and np.array_equal(graph.edge_cost, graph.edge_length)


def test_a_door_node_sees_both_ends_and_none_is_found_through_a_wall():
    world = two_rooms()
    belief = known(world)
    passable, clearance = belief == FREE, clearance_cells(belief)
    a, b = (22, 27), (32, 27)  # the nodes left and right of the wall, on its lattice row
    door, length = find_door_node(passable, clearance, a, b)
    assert door[0] == 27 and door[1] in (28, 29)
    assert length >= 10.0
    closed = passable.copy()
    closed[28:30, 27] = False
    assert find_door_node(closed, clearance, a, b) is None
    route = via_waypoints(passable, clearance, a, [b])
    assert route == [(door, True), (b, False)]
    assert via_waypoints(passable, clearance, a, [(17, 27)]) == [((17, 27), False)]


def test_door_edges_are_found_incrementally_as_the_belief_grows():
    world = two_rooms()
    protocol = PAPER_REAL_ROBOT
    whole, _ = reached_nodes(world, protocol)
    graph = LatticeGraph(LatticeSpec.for_map(world, protocol))
    belief = np.zeros(world.shape, np.uint8)  # unknown
    graph.update(belief)
    full = known(world)
    for rows in (slice(0, 30), slice(30, 60)):  # the left part first, then the rest
        before = belief.copy()
        belief[rows] = full[rows]
        graph.update(belief, np.flatnonzero(before != belief))
    assert np.array_equal(graph.edge_valid, whole.edge_valid)
    assert np.array_equal(graph.edge_via >= 0, whole.edge_via >= 0)
