import numpy as np

from pipeline.lattice.graph import NODE_FREE, NODE_OCCUPIED, NODE_UNKNOWN, LatticeGraph
from pipeline.lattice.spec import LatticeSpec
from pipeline.prediction.node_image import (
    PIXEL_FREE,
    PIXEL_OBSTACLE,
    PIXEL_UNKNOWN,
    centre_pad,
    node_image_pair,
    observed_node_states,
    pad_size_for,
)
from pipeline.world.sensor import FREE, OCCUPIED, UNKNOWN


def test_pad_sizes_follow_the_paper():
    assert pad_size_for((25, 25)) == 32
    assert pad_size_for((33, 20)) == 40
    assert pad_size_for((46, 46)) == 48
    assert pad_size_for((60, 60)) == 48  # centre-cropped


def test_centre_pad_marks_valid_pixels():
    canvas, valid = centre_pad(np.full((3, 5), 7, np.uint8), 8, 128)
    assert canvas.shape == (8, 8) and valid.sum() == 15
    assert (canvas[valid] == 7).all() and (canvas[~valid] == 128).all()
    cropped, valid = centre_pad(np.arange(100, dtype=np.uint8).reshape(10, 10), 4, 0)
    assert valid.all() and cropped[0, 0] == 33


def test_pair_rasterises_nodes_from_the_belief():
    spec = LatticeSpec((100, 100), (50, 50), 0.4, 4.0, 10.0, 20.0)
    graph = LatticeGraph(spec)
    ground = np.ones((100, 100), dtype=bool)
    ground[:, 70:] = False
    belief = np.full((100, 100), UNKNOWN, dtype=np.uint8)
    belief[40:61, 40:61] = FREE
    belief[50, 70] = OCCUPIED
    pair = node_image_pair(graph, belief, ground)
    assert pair.observed.shape == (32, 32)
    rows, cols = graph.lattice_shape
    r0, c0 = (32 - rows) // 2, (32 - cols) // 2
    centre = (r0 + graph.node_id(0, 0) // cols, c0 + graph.node_id(0, 0) % cols)
    assert pair.observed[centre] == PIXEL_FREE
    right = graph.node_id(2, 0)
    assert pair.observed[r0 + right // cols, c0 + right % cols] == PIXEL_OBSTACLE
    assert pair.target[r0 + right // cols, c0 + right % cols] == PIXEL_OBSTACLE
    assert pair.target[centre] == PIXEL_FREE
    assert pair.unknown.sum() == (pair.observed[pair.valid] == PIXEL_UNKNOWN).sum() > 0
    assert (pair.observed[~pair.valid] == PIXEL_OBSTACLE).all()  # outside the map: nothing free there


def test_unknown_nodes_next_to_known_walls_are_drawn_as_obstacles():
    spec = LatticeSpec((100, 100), (50, 50), 0.4, 4.0, 10.0, 20.0)
    graph = LatticeGraph(spec)
    belief = np.full((100, 100), UNKNOWN, dtype=np.uint8)
    belief[45:56, 40:56] = FREE
    belief[45:56, 56] = OCCUPIED  # a wall surface 4 cells short of the node at cell (60, 50)
    states = observed_node_states(belief, graph)
    assert states[graph.node_id(1, 0)] == NODE_OCCUPIED  # cell (60, 50): unknown, 1.6 m from the wall
    assert states[graph.node_id(0, 0)] == NODE_FREE
    assert states[graph.node_id(3, 0)] == NODE_UNKNOWN  # cell (80, 50): far from anything known
    ground = np.ones((100, 100), dtype=bool)
    pair = node_image_pair(graph, belief, ground)
    assert (pair.observed[pair.valid] == PIXEL_OBSTACLE).sum() == (states == NODE_OCCUPIED).sum()
