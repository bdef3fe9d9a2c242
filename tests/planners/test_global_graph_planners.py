"""Tests of guide_tsp and mapex (pipeline/planners/global_graph_planners.py)."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.graph import LatticeGraph, LatticeSpec
from pipeline.maps import GroundTruthMap, load_maze_png
from pipeline.mazes import MazeConfig, generate_maze, write_maze_png
from pipeline.node_image import ground_truth_states, node_states_image
from pipeline.node_predictor import pad_to_multiple
from pipeline.planners import global_graph_planners as ggp
from pipeline.planners import make_planner, planner_names
from pipeline.protocol import Protocol
from pipeline.sensor import FREE, UNKNOWN
from pipeline.simulator import Episode, run_episode

PROTOCOL = Protocol()


@pytest.fixture(scope="module")
def maze(tmp_path_factory) -> GroundTruthMap:
    path = tmp_path_factory.mktemp("ggp") / "maze_50m.png"
    write_maze_png(generate_maze(MazeConfig(side_m=(50.0, 50.0)), np.random.default_rng(3)), path)
    return load_maze_png(path)


def oracle_inpainter(ground_truth: GroundTruthMap):
    """A stand-in network that knows the ground-truth node image."""
    graph = LatticeGraph(LatticeSpec.for_map(ground_truth, PROTOCOL))
    truth = node_states_image(graph, ground_truth_states(graph, ground_truth.free))
    padded, _ = pad_to_multiple(truth, 8, 128)
    return lambda image: (padded == 255).astype(np.float32)


@pytest.fixture(autouse=True)
def no_default_model(monkeypatch, tmp_path):
    """Tests never pick up a trained model from the working tree."""
    monkeypatch.setattr(ggp, "DEFAULT_CHECKPOINT", tmp_path / "absent" / "inpainter.pt")


def test_both_planners_are_registered():
    assert {"guide_tsp", "mapex"} <= set(planner_names())


@pytest.mark.parametrize("name", ["guide_tsp", "mapex"])
@pytest.mark.parametrize("with_oracle", [True, False])
def test_episode_completes_without_motion_violations(maze, name, with_oracle):
    options = {"inpaint": oracle_inpainter(maze)} if with_oracle else {}
    planner = make_planner(name, **options)
    assert ("injected" in planner.description) == with_oracle
    assert ("frontier-only" in planner.description) != with_oracle
    result = run_episode(maze, planner, PROTOCOL)
    assert result.complete, result.failure
    assert result.motion_violations == 0
    assert result.failure == ""


@pytest.mark.parametrize("name", ["guide_tsp", "mapex"])
def test_oracle_predictions_are_used_and_steps_follow_known_edges(maze, name):
    planner = make_planner(name, inpaint=oracle_inpainter(maze))
    episode = Episode(maze, PROTOCOL)
    planner.reset(maze, PROTOCOL, 0)
    predicted_seen = 0
    for _ in range(6):
        observation = episode.observe()
        waypoints = planner.plan(observation)
        assert len(waypoints) == 1
        graph = planner.graph
        here, there = planner.robot_node(observation), graph.nearest_node(waypoints[0])
        assert np.allclose(graph.node_world[there], waypoints[0])
        assert there in set(graph.neighbours(here).tolist())  # a known-free lattice edge
        predicted_seen += planner.last_decision["predicted"]
        episode.move(waypoints[0])
    assert predicted_seen > 0


def test_guide_tsp_targets_are_spread_and_bounded(maze):
    planner = make_planner("guide_tsp", inpaint=oracle_inpainter(maze), top_k=3, spread=8.0)
    episode = Episode(maze, PROTOCOL)
    planner.reset(maze, PROTOCOL, 0)
    planner.plan(episode.observe())
    targets = planner.last_decision["targets"]
    assert 1 <= len(targets) <= 3
    xy = planner.graph.node_world[targets]
    d = np.hypot(xy[:, None, 0] - xy[None, :, 0], xy[:, None, 1] - xy[None, :, 1])
    assert (d[~np.eye(len(targets), dtype=bool)] >= 8.0).all()
    assert sorted(planner.last_decision["tour"]) == sorted(targets.tolist())


def test_mapex_paints_only_unknown_cells_near_predicted_nodes(maze):
    planner = make_planner("mapex")
    planner.reset(maze, PROTOCOL, 0)
    graph = planner.graph
    belief = np.full(maze.shape, UNKNOWN, dtype=np.uint8)
    node = graph.node_count // 2
    cx, cy = graph.node_cells[node]
    belief[cy, cx + 1] = FREE
    painted = planner.predicted_free_cells(belief, np.array([node]))
    assert painted[cy, cx] and not painted[cy, cx + 1]
    radius = graph.spec.node_step_cells / 2
    ys, xs = np.nonzero(painted)
    assert (np.hypot(xs - cx, ys - cy) <= radius + 0.5).all()
    assert not planner.predicted_free_cells(belief, np.zeros(0, dtype=np.int64)).any()


def test_a_missing_checkpoint_is_an_error():
    with pytest.raises(FileNotFoundError, match="checkpoint"):
        make_planner("guide_tsp", checkpoint="/nonexistent/inpainter.pt")
