"""Lattice planners that predict free nodes V_p in unknown space (Algorithm 1), with the node predictor.

The inpainter: an `inpaint` callable (uint8 node image -> free probability; tests pass an
oracle) wins; else the `inpainter_file` option's file; else the pipeline's trained inpainter, else the shipped
one (`pipeline.models.defaults`). With none, nothing is predicted and the planner reduces to
its frontier-only version (the instance's `description` says which predictor is in use).
"""

from __future__ import annotations

import warnings
from typing import TYPE_CHECKING, Annotated, ClassVar

import numpy as np
from pydantic import InstanceOf

from pipeline.common.config import config_dataclass, fraction, maybe, text, whole
from pipeline.lattice.graph import LatticeGraph
from pipeline.models.defaults import inpainter_protocol, resolve_inpainter
from pipeline.planners.config import option
from pipeline.planners.graph_planner import GraphPlanner, LatticePlannerConfig
from pipeline.prediction.global_graph import GlobalGraph, GlobalGraphConfig
from pipeline.prediction.node_predictor import (
    DEFAULT_COUNT_THRESHOLD,
    DEFAULT_THRESHOLD,
    InpaintFn,
    NodePredictor,
    NodePredictorConfig,
)
from pipeline.world.maps import MapFrame
from pipeline.world.planner import Observation
from pipeline.world.protocol import Protocol, ProtocolMismatchWarning, model_input_differences

if TYPE_CHECKING:
    from pipeline.prediction.prediction_trust import TrustedPredictor


@config_dataclass
class PredictorOptions(LatticePlannerConfig):
    """The options of a planner that predicts free nodes in unknown space (Algorithm 1)."""

    part = "the node predictor (Sec. IV-B)"

    # an injected inpainter (node image -> free probability): tests pass an oracle
    objects: ClassVar[tuple[str, ...]] = ("inpaint",)
    renamed = {"checkpoint": "inpainter_file"}

    inpainter_file: Annotated[str | None, maybe(text())] = option(
        None, "the inpainter export [default: models/inpainter/inpainter.pt, else the shipped one]"
    )
    threshold: Annotated[float, fraction()] = option(
        DEFAULT_THRESHOLD, "tau: an unknown node is predicted free at P(free) >= tau"
    )
    min_component: Annotated[int, whole(0, note="0 or 1 = keep every prediction")] = option(
        3, "predicted nodes in smaller 8-connected components are dropped (0 or 1: keep all)"
    )

    def model_slots(self) -> dict[str, str]:
        predicts = getattr(self, "predicts", True)  # dare's observed graph loads no inpainter
        return {**super().model_slots(), **({"inpainter_file": "inpainter"} if predicts else {})}


@config_dataclass
class GlobalGraphOptions(PredictorOptions):
    """The options of a planner that builds the global graph of Sec. IV-B from its predictions."""

    part = "the global graph (Sec. IV-B)"

    count_threshold: Annotated[float | None, maybe(fraction(), "threshold")] = option(
        DEFAULT_COUNT_THRESHOLD, "tau of the predicted nodes the utility boost counts [None: threshold]"
    )
    global_graph: Annotated[GlobalGraphConfig, InstanceOf[GlobalGraphConfig]] = option(
        GlobalGraphConfig(), "the global graph's settings: region size and score (r(g)), node window (a Python object)"
    )


class PredictingPlanner(GraphPlanner):
    """A lattice-graph planner with a node predictor (or none)."""

    base_description = ""

    def __init__(self, config: PredictorOptions, inpaint: InpaintFn | None = None):
        super().__init__(config)
        checkpoint, threshold, min_component = config.inpainter_file, config.threshold, config.min_component
        count_threshold = getattr(config, "count_threshold", None)  # the utility boost's tau, where there is one
        if getattr(config, "predicts", True):
            fn, source, path = resolve_inpainter(inpaint, checkpoint)
        else:  # the observed graph only (dare): no inpainter is loaded
            fn, source, path = None, "no prediction (observed graph only)", None
        predictor_config = NodePredictorConfig(threshold, int(min_component), count_threshold=count_threshold)
        # The node predictor; a `TrustedPredictor` around it once the trust wrapper holds this planner.
        self.predictor: NodePredictor | TrustedPredictor | None = (
            None if fn is None else NodePredictor(fn, predictor_config)
        )
        self.predictor_source = source
        # (model, protocol recorded with it) for every trained model this planner runs; checked at reset.
        self.trained_models: list[tuple[str, dict | None]] = (
            [] if path is None else [(str(path), inpainter_protocol(path))]
        )
        self.description = f"{self.base_description} [{source}; {self.gate_source}]"
        self.last_decision: dict = {}

    def reset(self, frame: MapFrame, protocol: Protocol, seed: int) -> None:
        super().reset(frame, protocol, seed)
        self.check_protocol(protocol)

    def check_protocol(self, protocol: Protocol) -> None:
        # A model sees node images and graphs drawn at the protocol it was trained at; others still run.
        for model, trained in self.trained_models:
            differences = model_input_differences(trained, protocol)
            if differences:  # one warning per model and protocol: the same text from this one line
                warnings.warn(
                    f"{model} was trained at other protocol values ({', '.join(differences)}): its inputs mean "
                    f"something else here, so expect weaker predictions; retrain at your maps' values "
                    f"(params.yaml: protocol)",
                    ProtocolMismatchWarning,
                )

    def predict(self) -> np.ndarray:
        """V_p at `threshold`."""
        if self.predictor is None or self.graph is None:
            return np.zeros(0, dtype=np.int64)
        return self.predictor.predict(self.graph)

    def predict_with_counted(self) -> tuple[np.ndarray, np.ndarray]:
        """(V_p at `threshold` for the graph, V_p at `count_threshold` for the utility boost)."""
        if self.predictor is None or self.graph is None:
            none = np.zeros(0, dtype=np.int64)
            return none, none
        return self.predictor.predict_with_counted(self.graph)

    def locate(self, observation: Observation) -> tuple[LatticeGraph, int, np.ndarray, np.ndarray, np.ndarray]:
        """Every decision's start: the updated graph, the robot's node, known-graph distances and
        predecessors from it, and the useful nodes it can reach (empty: nothing left to explore)."""
        graph = self.update_graph(observation)
        robot = self.robot_node(observation)
        dist, pred = graph.shortest_paths(robot)
        return graph, robot, dist, pred, self.reachable_useful(robot, dist)


class GlobalGraphPlanner(PredictingPlanner):
    """A predicting planner that builds the global graph of Sec. IV-B at each decision: the known
    nodes, the predicted nodes region evaluation keeps (r(g)), centroids, boosted utilities u(v)."""

    def __init__(self, config: GlobalGraphOptions, inpaint: InpaintFn | None = None):
        super().__init__(config, inpaint)
        self.global_config: GlobalGraphConfig = config.global_graph

    def reset(self, frame: MapFrame, protocol: Protocol, seed: int) -> None:
        super().reset(frame, protocol, seed)
        assert self.graph is not None
        self.global_graph = GlobalGraph(self.graph, self.global_config)

    def update_global_graph(self, observation: Observation) -> np.ndarray:
        """Predict V_p and rebuild the global graph from the updated lattice graph; the predicted nodes."""
        predicted, counted = self.predict_with_counted()
        self.global_graph.update(observation.belief, observation.position, predicted, self.visited, counted)
        return predicted
