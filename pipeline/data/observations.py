"""Stage II training data: expert episodes replayed into graph observations with the frozen predictor.

Each stored expert step is rebuilt exactly (belief diffs), the lattice graph is updated
incrementally, the Global Node Predictor runs once, and two observations are made from
the same step: `guide` (the region-evaluated global graph with predicted nodes and
centroids) and `dare` (the observed graph alone). The action is the expert's next T_p
lattice steps. Samples are stored flat with their episode id so that T_o-step histories
never cross an episode boundary.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, cast

import numpy as np

from pipeline.common.atomic import atomic_file
from pipeline.data.expert_episodes import ExpertEpisode, load_expert_episodes
from pipeline.lattice.graph import LatticeGraph
from pipeline.lattice.spec import LatticeSpec
from pipeline.models.defaults import cached_inpainter
from pipeline.prediction.global_graph import GlobalGraph, GlobalGraphConfig
from pipeline.prediction.graph_observation import expert_action_deltas, observe, rotate_steps
from pipeline.prediction.node_predictor import NodePredictor, NodePredictorConfig
from pipeline.world.maps import GroundTruthMap
from pipeline.world.protocol import Protocol

VARIANTS = ("guide", "dare")
ARRAY_KEYS = ("features", "node_mask", "neighbors", "robot", "actions", "episode", "step")


@dataclass(frozen=True)
class ObservationConfig:
    max_nodes: int = 320
    max_neighbors: int = 25


def episode_ground_truth(episode: ExpertEpisode, protocol: Protocol) -> GroundTruthMap:
    return GroundTruthMap(episode.ground_truth, episode.start_cell, protocol.cell_size, episode.map_name)


def episode_observations(
    episode: ExpertEpisode,
    protocol: Protocol,
    predictor: NodePredictor | None,
    config: ObservationConfig = ObservationConfig(),
    episode_id: int = 0,
    variants: tuple[str, ...] = VARIANTS,
) -> dict[str, dict[str, np.ndarray]]:
    """{variant: arrays} for every step of one expert episode, for each of `variants`."""
    ground_truth = episode_ground_truth(episode, protocol)
    lattice = LatticeGraph(LatticeSpec.for_map(ground_truth, protocol))
    unknown = set(variants) - set(VARIANTS)
    if unknown:
        raise ValueError(f"unknown observation variants {sorted(unknown)}; choose from {', '.join(VARIANTS)}")
    graphs = {
        "guide": GlobalGraph(lattice, GlobalGraphConfig(max_nodes=config.max_nodes)),
        "dare": GlobalGraph(lattice, GlobalGraphConfig(max_nodes=config.max_nodes, use_region_evaluation=False)),
    }
    graphs = {variant: graph for variant, graph in graphs.items() if variant in variants}
    visited = np.zeros(lattice.node_count, dtype=bool)
    out: dict[str, dict[str, list]] = {v: {k: [] for k in ARRAY_KEYS} for v in graphs}
    previous = None
    for step, belief in enumerate(episode.beliefs()):
        changed = None if previous is None else np.flatnonzero(previous != belief)
        lattice.update(belief, changed)
        previous = belief.copy()
        position = episode.positions[step].astype(np.float64)
        visited[lattice.nearest_node(position)] = True
        actions = expert_action_deltas(position, episode.future_waypoints[step], protocol.node_resolution)
        if predictor is not None:
            predicted, counted = predictor.predict_with_counted(lattice)
        else:
            predicted = counted = np.zeros(0, dtype=np.int64)
        for variant, graph in graphs.items():
            if variant == "guide":
                graph.update(previous, position, predicted, visited, counted)
            else:
                graph.update(previous, position, None, visited)
            obs = observe(graph, position, config.max_neighbors)
            arrays = out[variant]
            arrays["features"].append(obs.features.astype(np.float16))
            arrays["node_mask"].append(obs.node_mask)
            arrays["neighbors"].append(obs.neighbors)
            arrays["robot"].append(obs.robot)
            arrays["actions"].append(actions.astype(np.int8))
            arrays["episode"].append(episode_id)
            arrays["step"].append(step)
    return {v: {k: np.asarray(a) for k, a in arrays.items()} for v, arrays in out.items()}


def shard_observations(
    shard: str | Path,
    first_episode_id: int,
    protocol: Protocol,
    inpainter: str | Path,
    settings: dict,
    variants: tuple[str, ...] = VARIANTS,
) -> dict[str, dict[str, np.ndarray]]:
    """{variant: arrays} for every episode of one Stage II shard (expert or DAgger), replayed with the
    inpainter at `inpainter` and the predictor and observation `settings` (threshold,
    count_threshold, min_component, max_nodes, max_neighbors); episode ids from `first_episode_id`.
    Runs in a worker process: one torch thread."""
    import torch

    torch.set_num_threads(1)
    predictor = NodePredictor(
        cached_inpainter(inpainter),
        NodePredictorConfig(
            settings["threshold"], settings["min_component"], count_threshold=settings["count_threshold"]
        ),
    )
    config = ObservationConfig(settings["max_nodes"], settings["max_neighbors"])
    parts = [
        episode_observations(episode, protocol, predictor, config, episode_id=first_episode_id + k, variants=variants)
        for k, episode in enumerate(load_expert_episodes(shard))
    ]
    return {variant: concatenate(p[variant] for p in parts) for variant in variants}


def concatenate(parts: Iterable[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    parts = list(parts)
    if not parts:
        raise ValueError("no observations to concatenate")
    return {k: np.concatenate([p[k] for p in parts]) for k in ARRAY_KEYS}


def save_observations(path: str | Path, arrays: dict[str, np.ndarray], meta: dict) -> None:
    import json

    with atomic_file(path) as tmp:  # the temporary name ends in .npz too, so numpy adds no suffix
        np.savez_compressed(tmp, meta=np.array(json.dumps(meta)), **cast(dict[str, Any], arrays))


def load_observations(path: str | Path) -> tuple[dict[str, np.ndarray], dict]:
    import json

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no observations; run the build_observations stage first")
    with np.load(path, allow_pickle=False) as data:
        missing = [k for k in ARRAY_KEYS if k not in data.files]
        if missing:
            raise ValueError(f"{path}: not an observation file (missing {', '.join(missing)})")
        arrays = {k: data[k] for k in ARRAY_KEYS}
        meta = json.loads(str(data["meta"])) if "meta" in data.files else {}
    return arrays, meta


def crop_observations(arrays: dict[str, np.ndarray], max_nodes: int) -> dict[str, np.ndarray]:
    """The same observations limited to their `max_nodes` nearest rows (rows are sorted nearest first).

    Neighbour indices into dropped rows become padding; the robot's row is the nearest, row 0.
    Lets one observation set train models of several sizes.
    """
    stored = arrays["features"].shape[1]
    if max_nodes > stored:
        raise ValueError(f"cannot crop observations of {stored} nodes to {max_nodes}")
    if max_nodes == stored:
        return arrays
    if (arrays["robot"] >= max_nodes).any():
        raise ValueError("the robot's row lies beyond the crop")
    neighbors = arrays["neighbors"][:, :max_nodes].copy()
    neighbors[neighbors >= max_nodes] = -1
    return {
        **arrays,
        "features": arrays["features"][:, :max_nodes],
        "node_mask": arrays["node_mask"][:, :max_nodes],
        "neighbors": neighbors,
    }


def history_index(episode: np.ndarray, step: np.ndarray, obs_steps: int) -> np.ndarray:
    """(S, T_o) sample rows making each sample's observation history (the episode's first repeats)."""
    rows = np.arange(len(episode))[:, None] + np.arange(-obs_steps + 1, 1)[None, :]
    rows = np.clip(rows, 0, None)
    # Rows before the episode's first step are replaced by that first step.
    first = np.arange(len(episode)) - step.astype(np.int64)
    return np.maximum(rows, first[:, None])


class PlannerDataset:
    """Torch-style dataset of (T_o observations, T_p actions), with random dihedral augmentation."""

    def __init__(
        self,
        arrays: dict[str, np.ndarray],
        obs_steps: int,
        rows: np.ndarray | None = None,
        augment: bool = False,
        seed: int = 0,
    ):
        self.arrays = arrays
        self.history = history_index(arrays["episode"], arrays["step"], obs_steps)
        self.rows = np.arange(len(arrays["episode"])) if rows is None else np.asarray(rows)
        self.augment = augment
        self.rng = np.random.default_rng(seed)

    def __len__(self) -> int:
        return len(self.rows)

    def __getitem__(self, i: int) -> dict:
        import torch

        row = int(self.rows[i])
        hist = self.history[row]
        a = self.arrays
        features = a["features"][hist].astype(np.float32)
        actions = a["actions"][row].astype(np.int64)
        if self.augment:
            k, flip = int(self.rng.integers(4)), bool(self.rng.integers(2))
            features[..., 0:2] = rotate_steps(features[..., 0:2], k, flip)
            actions = rotate_steps(actions, k, flip)
        return {
            "features": torch.from_numpy(features),
            "node_mask": torch.from_numpy(a["node_mask"][hist]),
            "neighbors": torch.from_numpy(a["neighbors"][hist].astype(np.int64)),
            "robot": torch.from_numpy(a["robot"][hist].astype(np.int64)),
            "actions": torch.from_numpy(actions),
        }
