"""Node images: the lattice rasterised one pixel per node, the inpainter's input and target.

255 marks a free node, 0 an obstacle node, 128 an unknown one (DARE/GUIDE's release). The
image is centre-padded to the smallest of the paper's sizes (32, 40, 48) that holds the
lattice; padding is drawn as obstacle in the input (`PIXEL_PADDING`) and flagged invalid
so no loss is taken there.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from pipeline.lattice.graph import NODE_FREE, NODE_OCCUPIED, NODE_UNKNOWN, LatticeGraph, node_states_in
from pipeline.world.sensor import OCCUPIED

PIXEL_FREE, PIXEL_OBSTACLE, PIXEL_UNKNOWN = 255, 0, 128
PIXEL_PADDING = PIXEL_OBSTACLE
"""Pixels outside the map. The authors' release pads with unknown, but then the network cannot
tell where the map ends, and nothing beyond it is free: it predicted free nodes inside the
outer wall."""
PAD_SIZES = (32, 40, 48)


@dataclass(frozen=True)
class NodeImagePair:
    """One Stage I sample: observed node image, ground-truth node image, masks."""

    observed: np.ndarray  # uint8 (S, S): 255 free, 0 obstacle, 128 unknown
    target: np.ndarray  # uint8 (S, S): 255 free, 0 not free
    valid: np.ndarray  # bool (S, S): inside the lattice (False on padding)

    @property
    def unknown(self) -> np.ndarray:
        """The inpainting mask: unknown pixels inside the lattice."""
        return (self.observed == PIXEL_UNKNOWN) & self.valid


def node_states_image(graph: LatticeGraph, states: np.ndarray) -> np.ndarray:
    """Rasterise per-node states (NODE_*) into the lattice's (rows = y, cols = x) image."""
    image = np.full(graph.lattice_shape, PIXEL_UNKNOWN, dtype=np.uint8)
    flat = image.reshape(-1)
    flat[states == NODE_FREE] = PIXEL_FREE
    flat[states == NODE_OCCUPIED] = PIXEL_OBSTACLE
    return image


def pad_size_for(shape: tuple[int, int], sizes: tuple[int, ...] = PAD_SIZES) -> int:
    """The smallest pad size holding the lattice; larger lattices are centre-cropped to the largest."""
    need = max(shape)
    for size in sizes:
        if need <= size:
            return size
    return sizes[-1]


def centre_pad(image: np.ndarray, size: int, fill: int) -> tuple[np.ndarray, np.ndarray]:
    """Centre `image` in a size x size canvas (cropping the middle if larger); returns (canvas, valid)."""
    canvas = np.full((size, size), fill, dtype=image.dtype)
    valid = np.zeros((size, size), dtype=bool)
    rows, cols = image.shape
    src_r0, src_c0 = max(0, (rows - size) // 2), max(0, (cols - size) // 2)
    crop = image[src_r0 : src_r0 + size, src_c0 : src_c0 + size]
    r0, c0 = (size - crop.shape[0]) // 2, (size - crop.shape[1]) // 2
    canvas[r0 : r0 + crop.shape[0], c0 : c0 + crop.shape[1]] = crop
    valid[r0 : r0 + crop.shape[0], c0 : c0 + crop.shape[1]] = True
    return canvas, valid


def ground_truth_states(graph: LatticeGraph, ground_free: np.ndarray) -> np.ndarray:
    """Each node's true state: free where its cell is free in the ground truth, else obstacle."""
    states = np.full(graph.node_count, NODE_OCCUPIED, dtype=np.int8)
    states[ground_free.reshape(-1)[graph.node_flat]] = NODE_FREE
    return states


WALL_RADIUS_NODES = 0.6
"""Unknown nodes this close to a known obstacle cell (in node spacings: 2.4 m at d_n = 4 m) are
drawn as obstacles in the node image.

A node inside a 5 m wall is never observed (the lidar reveals wall surfaces only), so left
unknown it teaches the inpainter that "unknown next to free" means wall. Almost every node
this rule marks is a wall in the ground truth.
"""


def observed_node_states(
    belief: np.ndarray, graph: LatticeGraph, wall_radius_nodes: float = WALL_RADIUS_NODES
) -> np.ndarray:
    """Node states for the observed node image: the belief at each node, plus inferred walls."""
    states = node_states_in(belief, graph.node_flat)
    radius = int(round(wall_radius_nodes * graph.spec.node_step_cells))
    if radius >= 1:
        kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
        near_wall = cv2.dilate((belief == OCCUPIED).astype(np.uint8), kernel).reshape(-1)[graph.node_flat] > 0
        states[(states == NODE_UNKNOWN) & near_wall] = NODE_OCCUPIED
    return states


def node_image_pair(
    graph: LatticeGraph, belief: np.ndarray, ground_free: np.ndarray, sizes: tuple[int, ...] = PAD_SIZES
) -> NodeImagePair:
    """The (observed, ground truth) node-image pair for a belief on the graph's lattice."""
    observed = node_states_image(graph, observed_node_states(belief, graph))
    target = node_states_image(graph, ground_truth_states(graph, ground_free))
    size = pad_size_for(observed.shape, sizes)
    observed_padded, valid = centre_pad(observed, size, PIXEL_PADDING)
    target_padded, _ = centre_pad(target, size, PIXEL_OBSTACLE)
    return NodeImagePair(observed_padded, target_padded, valid)
