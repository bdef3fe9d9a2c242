"""Global Node Predictor (paper Algorithm 1): free nodes predicted in unknown space.

Rasterise V_f and V_o one pixel per lattice node, centre-pad to a multiple of the network's
stride (padding drawn as obstacle, `PIXEL_PADDING`), inpaint, binarise at tau, and drop
predicted nodes in small connected components. The same probabilities binarised at a lower
tau give the nodes the utility boost counts. The inpainting model is any callable from a
uint8 node image to free-node probabilities, so the predictor does not care which network
(or test double) runs.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import cv2
import numpy as np

from pipeline.lattice.graph import NODE_FREE, NODE_UNKNOWN, LatticeGraph
from pipeline.prediction.node_image import PIXEL_PADDING, node_states_image, observed_node_states

InpaintFn = Callable[[np.ndarray], np.ndarray]
"""(S, S) uint8 node image (255 free, 0 obstacle, 128 unknown) -> (S, S) free-node probability."""


# Two operating points of one prediction. tau (DEFAULT_THRESHOLD) picks the predicted nodes that
# enter the global graph, V_p and after region evaluation V_u, which Table I measures; the count
# tau (DEFAULT_COUNT_THRESHOLD) picks the predicted nodes the utility boost N_u counts.
# One tau for both forced a trade: the graph wants few, precise nodes, the boost a broad count of
# likely-free space; two taus give each its own.
DEFAULT_THRESHOLD = 0.8
DEFAULT_COUNT_THRESHOLD = 0.5


@dataclass(frozen=True)
class NodePredictorConfig:
    threshold: float = DEFAULT_THRESHOLD  # tau: probability at or above which an unknown node is predicted free
    min_component: int = 3  # predicted nodes in smaller 8-connected components are dropped
    stride: int = 8  # the network's total downsampling: images are padded to a multiple of it
    count_threshold: float | None = (
        DEFAULT_COUNT_THRESHOLD  # tau of the nodes the utility boost counts (None: threshold)
    )


def pad_to_multiple(image: np.ndarray, multiple: int, fill: int) -> tuple[np.ndarray, tuple[int, int]]:
    """Centre-pad to the next multiple of `multiple` on each side, two multiples at least; returns
    (image, (row0, col0)). After the network's downsampling by `multiple` each side keeps two pixels,
    which its reflect-padded 3x3 convolutions need: a lattice one or two nodes across (a corridor
    wing) would otherwise leave one, and the convolution would fail."""
    rows, cols = image.shape
    size_r = max(2, -(-rows // multiple)) * multiple
    size_c = max(2, -(-cols // multiple)) * multiple
    r0, c0 = (size_r - rows) // 2, (size_c - cols) // 2
    canvas = np.full((size_r, size_c), fill, dtype=image.dtype)
    canvas[r0 : r0 + rows, c0 : c0 + cols] = image
    return canvas, (r0, c0)


def drop_small_components(predicted: np.ndarray, known_free: np.ndarray, min_size: int) -> np.ndarray:
    """Keep predicted pixels whose 8-connected component (with known free pixels) has >= min_size pixels."""
    if min_size <= 1 or not predicted.any():
        return predicted
    mask = (predicted | known_free).astype(np.uint8)
    count, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    sizes = stats[:, cv2.CC_STAT_AREA]
    return predicted & (sizes[labels] >= min_size)


class NodePredictor:
    """Predicts V_p, the lattice nodes in unknown space that are likely free."""

    def __init__(self, inpaint: InpaintFn, config: NodePredictorConfig = NodePredictorConfig()):
        self.inpaint = inpaint
        self.config = config

    def probabilities(self, graph: LatticeGraph, states: np.ndarray | None = None) -> np.ndarray:
        """Free-node probability per lattice node (the network's output on the node image).

        `states` are the observed node states when the caller already has them.
        """
        if states is None:
            states = observed_node_states(graph.belief, graph)
        image = node_states_image(graph, states)
        padded, (r0, c0) = pad_to_multiple(image, self.config.stride, PIXEL_PADDING)
        probability = np.asarray(self.inpaint(padded), dtype=np.float32)
        if probability.shape != padded.shape:
            raise ValueError(f"the inpainter returned shape {probability.shape} for an image of {padded.shape}")
        rows, cols = image.shape
        return probability[r0 : r0 + rows, c0 : c0 + cols].reshape(-1)

    def predict(self, graph: LatticeGraph) -> np.ndarray:
        """Ids of the predicted free nodes V_p (all currently unknown lattice nodes)."""
        states = observed_node_states(graph.belief, graph)
        return self.above(graph, states, self.probabilities(graph, states), self.config.threshold)

    def predict_with_counted(self, graph: LatticeGraph) -> tuple[np.ndarray, np.ndarray]:
        """(V_p at threshold, the nodes the utility boost counts: V_p at count_threshold), one inpainting."""
        states = observed_node_states(graph.belief, graph)
        probability = self.probabilities(graph, states)
        predicted = self.above(graph, states, probability, self.config.threshold)
        count_tau = self.config.count_threshold
        if count_tau is None or count_tau == self.config.threshold:
            return predicted, predicted
        return predicted, self.above(graph, states, probability, count_tau)

    def above(self, graph: LatticeGraph, states: np.ndarray, probability: np.ndarray, tau: float) -> np.ndarray:
        """Unknown nodes at P(free) >= tau, less those in small components."""
        shape = graph.lattice_shape
        predicted = (states == NODE_UNKNOWN) & (probability >= tau)
        kept = drop_small_components(
            predicted.reshape(shape), (graph.node_state == NODE_FREE).reshape(shape), self.config.min_component
        )
        return np.nonzero(kept.reshape(-1))[0]
