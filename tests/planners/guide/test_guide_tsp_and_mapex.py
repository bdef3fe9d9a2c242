"""Tests of guide_tsp and mapex (pipeline/planners/guide/guide_tsp.py, pipeline/planners/baselines/mapex.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pipeline.lattice.graph import LatticeGraph
from pipeline.lattice.spec import LatticeSpec
from pipeline.models import defaults
from pipeline.planners import make_planner, planner_names
from pipeline.planners.extensions.tour_vote import TourVote
from pipeline.planners.registry import make_config
from pipeline.planners.wrapper import innermost, layer
from pipeline.prediction.node_image import ground_truth_states, node_states_image
from pipeline.prediction.node_predictor import pad_to_multiple
from pipeline.world.maps import GroundTruthMap, load_maze_png
from pipeline.world.mazes import MazeConfig, generate_maze, write_maze_png
from pipeline.world.protocol import Protocol
from pipeline.world.sensor import FREE, UNKNOWN
from pipeline.world.simulator import Episode, run_episode
from tests.conftest import SINGLE_NODES

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
def no_shipped_model(monkeypatch, tmp_path):
    """These tests build the predictor planners without any inpainter unless they give one
    (conftest already hides models/ in the working tree)."""
    pipeline = defaults.MODEL_FILES["inpainter"][0]
    monkeypatch.setitem(defaults.MODEL_FILES, "inpainter", (pipeline, (tmp_path / "absent" / "shipped.pt",)))


def test_the_shipped_default_inpainter_is_used_when_the_pipeline_has_none(monkeypatch):
    shipped = defaults.ASSETS / "inpainter.pt"
    if not shipped.is_file():
        pytest.fail("the package ships pipeline/assets/inpainter.pt")
    monkeypatch.setitem(defaults.MODEL_FILES, "inpainter", (defaults.MODEL_FILES["inpainter"][0], (shipped,)))
    planner = make_planner("guide_tsp")
    assert "shipped default inpainter" in planner.description and innermost(planner).predictor is not None


def test_the_shipped_models_record_the_protocol_they_were_trained_at():
    """pipeline/assets/README.md: the maze benchmark's defaults, which the planners check against."""
    from pipeline.models.defaults import SHIPPED_POLICY
    from pipeline.models.modeling_diffusion import read_policy_export
    from pipeline.models.modeling_inpainter import read_inpainter_export

    shipped = defaults.ASSETS / "inpainter.pt"
    # Recorded before the protocol had a robot radius and a door-graph switch: those read as the defaults.
    assert Protocol.from_dict(read_inpainter_export(shipped)["protocol"]) == Protocol()
    for path in SHIPPED_POLICY.values():
        assert Protocol.from_dict(read_policy_export(path)["observations"]["protocol"]) == Protocol(), path


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
        graph = innermost(planner).graph
        here, there = innermost(planner).robot_node(observation), graph.nearest_node(waypoints[0])
        assert np.allclose(graph.node_world[there], waypoints[0])
        assert there in set(graph.neighbours(here).tolist())  # a known-free lattice edge
        predicted_seen += planner.last_decision["predicted"]
        episode.move(waypoints[0])
    assert predicted_seen > 0


def test_guide_tsp_targets_are_clusters_of_useful_nodes_and_bounded(maze):
    planner = make_planner("guide_tsp", inpaint=oracle_inpainter(maze), top_k=3, spread=8.0, min_weight=0.0)
    episode = Episode(maze, PROTOCOL)
    planner.reset(maze, PROTOCOL, 0)
    observation = episode.observe()
    planner.plan(observation)
    decision = planner.last_decision
    targets = decision["targets"]
    assert 1 <= len(targets) <= 3
    assert len(set(targets.tolist())) == len(targets)
    useful = set(innermost(planner).useful_nodes().tolist())
    assert set(targets.tolist()) <= useful
    assert sorted(decision["tour"]) == sorted(targets.tolist())
    assert decision["length"] > 0


def test_guide_tsp_clusters_join_within_spread_and_keep_the_previous_target(maze):
    planner = make_planner("guide_tsp", spread=10.0, min_weight=5.0)
    planner.reset(maze, PROTOCOL, 0)
    xy = innermost(planner).graph.node_world
    a = int(innermost(planner).graph.nearest_node((0.0, 0.0)))
    b = int(innermost(planner).graph.nearest_node((4.0, 0.0)))  # one lattice step from a: same cluster
    c = int(innermost(planner).graph.nearest_node((20.0, 0.0)))  # far: its own cluster, too light to keep
    assert np.hypot(*(xy[b] - xy[a])) < 10.0 <= np.hypot(*(xy[c] - xy[a]))
    candidates = np.array(sorted([a, b, c]))
    dist = np.zeros(innermost(planner).graph.node_count)
    dist[[a, b, c]] = [8.0, 4.0, 20.0]
    utility = np.array([{a: 10.0, b: 3.0, c: 2.0}[n] for n in candidates])
    targets, weights = innermost(planner).tour.select_targets(innermost(planner).graph, candidates, utility, dist)
    assert targets.tolist() == [b]  # a's cluster {a, b}: weight 13, target = the member nearer the robot
    assert weights.tolist() == [13.0]
    targets, weights = innermost(planner).tour.select_targets(
        innermost(planner).graph, candidates, utility, dist, keep=c
    )
    assert targets[0] == c  # the previous first target seeds a cluster and survives the weight filter


def test_spread_zero_makes_every_useful_node_its_own_target_as_guide_does_by_default(maze):
    """guide's default tour options: one option per useful node, none dropped for its weight."""
    planner = make_planner("guide_tsp", spread=0.0, min_weight=0.0)
    planner.reset(maze, PROTOCOL, 0)
    a, b, c = (
        int(innermost(planner).graph.nearest_node(p)) for p in ((0.0, 0.0), (4.0, 0.0), (8.0, 0.0))
    )  # neighbours in a row
    candidates = np.array(sorted([a, b, c]))
    dist = np.zeros(innermost(planner).graph.node_count)
    dist[[a, b, c]] = [4.0, 4.0, 8.0]  # a and b: one 4 m step apart, at the same distance
    utility = np.array([{a: 1.0, b: 3.0, c: 2.0}[n] for n in candidates])
    targets, weights = innermost(planner).tour.select_targets(innermost(planner).graph, candidates, utility, dist)
    assert targets.tolist() == [b, c, a] and weights.tolist() == [3.0, 2.0, 1.0]  # by utility, each on its own
    defaults = make_config("guide")[0]
    assert (defaults.spread, defaults.min_weight, defaults.beta) == (0.0, 0.0, 0.0)


def test_guide_tsp_keeps_its_target_through_a_cycle_on_an_unchanged_map(maze):
    """Replanning on an unchanged map flipped between two first targets and walked between two
    nodes until max_steps; back at a node with nothing new seen, the target chosen there is kept."""
    from pipeline.world.simulator import Observation

    planner = make_planner("guide_tsp")
    planner.reset(maze, PROTOCOL, 0)
    a, b, x, y = 1, 2, 7, 9  # two nodes the robot moves between, two targets the replanning flips between
    candidates = np.array([x, y])

    def decide(robot: int, first: int, news: bool) -> int:
        changed = np.array([5]) if news else np.zeros(0, dtype=np.int64)
        observation = Observation(belief=maze.free, position=(0.0, 0.0), cell=(0, 0), changed=changed, step=0)
        return innermost(planner).tour.keep_through_cycles(observation, robot, candidates, first)

    assert decide(a, x, news=True) == x
    assert decide(b, y, news=False) == y  # a new node: the fresh choice
    assert decide(a, y, news=False) == x  # back at a with nothing new: the choice made at a
    assert decide(b, y, news=False) == x  # and kept on the way there
    assert decide(b, y, news=True) == y  # something new seen: replan freely
    assert decide(a, x, news=False) == x
    assert decide(b, x, news=False) == y  # back at b: the choice made at b, whatever replanning says
    assert decide(a, x, news=False) == y
    assert decide(y, x, news=False) == x  # the kept target reached: released


def test_guide_tsp_rejects_bad_options():
    with pytest.raises(ValueError, match="top_k"):
        make_planner("guide_tsp", top_k=-1)
    with pytest.raises(ValueError, match="beta"):
        make_planner("guide_tsp", beta=-1.0)


def test_mapex_paints_only_unknown_cells_near_predicted_nodes(maze):
    planner = make_planner("mapex")
    planner.reset(maze, PROTOCOL, 0)
    graph = innermost(planner).graph
    belief = np.full(maze.shape, UNKNOWN, dtype=np.uint8)
    node = graph.node_count // 2
    cx, cy = graph.node_cells[node]
    belief[cy, cx + 1] = FREE
    painted = innermost(planner).predicted_free_cells(belief, np.array([node]))
    assert painted[cy, cx] and not painted[cy, cx + 1]
    radius = graph.spec.node_step_cells / 2
    ys, xs = np.nonzero(painted)
    assert (np.hypot(xs - cx, ys - cy) <= radius + 0.5).all()
    assert not innermost(planner).predicted_free_cells(belief, np.zeros(0, dtype=np.int64)).any()


def test_a_missing_checkpoint_is_an_error(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"inpainter\.pt: file not found \(expected an inpainter export\)"):
        make_planner("guide_tsp", inpainter_file="/nonexistent/inpainter.pt")
    with pytest.raises(FileNotFoundError, match=r"a folder, not a file"):
        make_planner("mapex", inpainter_file=str(tmp_path))


def test_guide_warns_when_its_policy_was_trained_at_other_taus(recwarn):
    """The shipped policy's observations were made at tau 0.8 / count 0.5: other taus run, with a warning."""
    import warnings

    from pipeline.models.defaults import SHIPPED_POLICY

    blank = lambda image: np.zeros(np.shape(image), np.float32)  # noqa: E731
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        make_planner("guide", policy_file=str(SHIPPED_POLICY["guide"]), inpaint=blank)
        make_planner(
            "dare", policy_file=str(SHIPPED_POLICY["dare"]), threshold=0.3
        )  # predicts nothing: no tau to match
    with pytest.warns(UserWarning, match=r"tau 0.8 \(utility count at 0.5\); this planner builds them at 0.5 \(0.5\)"):
        make_planner("guide", policy_file=str(SHIPPED_POLICY["guide"]), inpaint=blank, threshold=0.5)
    with pytest.warns(UserWarning, match=r"at 0.8 \(0.3\)"):
        make_planner("guide_noregion", policy_file=str(SHIPPED_POLICY["guide"]), inpaint=blank, count_threshold=0.3)


SHIPPED_INPAINTER = defaults.SHIPPED_INPAINTER


def copy_with_protocol(source: Path, target: Path, protocol: Protocol, *keys: str) -> Path:
    """A copy of an export with `protocol` recorded under payload[keys...]["protocol"]."""
    import torch

    payload = torch.load(source, map_location="cpu", weights_only=False)
    entry = payload
    for key in keys:
        entry = entry.setdefault(key, {})
    entry["protocol"] = protocol.to_dict()
    torch.save(payload, target)
    return target


@pytest.mark.parametrize("name", ["guide_tsp", "mapex"])
def test_predictor_planners_warn_when_their_inpainter_was_trained_at_another_protocol(name, maze, tmp_path):
    """The check runs at reset, when the protocol is known; an export without a record counts as the defaults."""
    import re
    import warnings

    from pipeline.world.protocol import ProtocolMismatchWarning

    halved = Protocol(node_resolution=2.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        make_planner(name, inpainter_file=str(SHIPPED_INPAINTER)).reset(maze, PROTOCOL, 0)
    expected = re.escape(f"{SHIPPED_INPAINTER} was trained at other protocol values (node_resolution 4 -> 2)")
    with pytest.warns(ProtocolMismatchWarning, match=expected):
        make_planner(name, inpainter_file=str(SHIPPED_INPAINTER)).reset(maze, halved, 0)
    recorded = copy_with_protocol(SHIPPED_INPAINTER, tmp_path / "inpainter_2m.pt", halved)
    planner = make_planner(name, inpainter_file=str(recorded))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        planner.reset(maze, halved, 0)
    with pytest.warns(ProtocolMismatchWarning, match=r"inpainter_2m\.pt was trained .*\(node_resolution 2 -> 4\)"):
        planner.reset(maze, PROTOCOL, 0)


def test_guide_warns_when_its_policy_was_trained_at_another_protocol(maze, tmp_path):
    """The policy's observations record the protocol they were built at; the export carries it."""
    import warnings

    from pipeline.models.defaults import SHIPPED_POLICY
    from pipeline.world.protocol import ProtocolMismatchWarning

    blank = lambda image: np.zeros(np.shape(image), np.float32)  # noqa: E731
    wide = Protocol(sensor_range=30.0, utility_range=15.0)
    policy = copy_with_protocol(SHIPPED_POLICY["guide"], tmp_path / "policy_30m.pt", wide, "observations")
    planner = make_planner("guide", policy_file=str(policy), inpaint=blank)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        planner.reset(maze, wide, 0)
    with pytest.warns(ProtocolMismatchWarning) as record:
        planner.reset(maze, PROTOCOL, 0)
    assert [str(w.message).split(" was trained")[0] for w in record] == [
        str(policy)
    ]  # the injected inpainter has no record
    assert "(sensor_range 30 -> 20, utility_range 15 -> 10)" in str(record[0].message)


@pytest.mark.parametrize("name, region_evaluation", [("guide", True), ("guide_noregion", False)])
def test_diffusion_planners_keep_a_global_graph_option_but_the_fields_their_policy_fixes(name, region_evaluation, maze):
    """max_nodes comes from the policy and region evaluation from the variant; the rest of the option is used."""
    from pipeline.models.defaults import SHIPPED_POLICY
    from pipeline.prediction.global_graph import GlobalGraphConfig

    blank = lambda image: np.zeros(np.shape(image), np.float32)  # noqa: E731
    option = GlobalGraphConfig(centroid_links=1, max_nodes=7, use_region_evaluation=not region_evaluation)
    planner = make_planner(name, policy_file=str(SHIPPED_POLICY["guide"]), inpaint=blank, global_graph=option)
    planner.reset(maze, PROTOCOL, 0)
    config = innermost(planner).global_graph.config
    assert config.centroid_links == 1
    assert config.use_region_evaluation is region_evaluation
    assert config.max_nodes == innermost(planner).policy.config.max_nodes


def test_without_regret_the_options_are_those_of_the_whole_tour(maze, monkeypatch):
    """guide's tour options (beta 0, a nearest-neighbour tour): scored from the distances of the
    robot and of the options alone, the same options, scores and first targets as when every
    target's distances and the whole tour are computed, at each decision of an episode."""
    from pipeline.planners.guide.guide_tsp import FrontierTour

    seen = []
    full = FrontierTour.first_target_scores

    def both(tour, graph, global_graph, robot, dist, candidates):
        previous = tour.previous
        fast = full(tour, graph, global_graph, robot, dist, candidates)
        with monkeypatch.context() as patch:
            patch.setattr(FrontierTour, "tour_scores", lambda self, points: True)
            tour.previous = previous
            whole = full(tour, graph, global_graph, robot, dist, candidates)
        assert np.array_equal(fast["firsts"], whole["firsts"])
        assert np.allclose(fast["scores"], whole["scores"], rtol=1e-12, atol=0)
        assert [t[0] for t in fast["tours"]] == [t[0] for t in whole["tours"]]
        assert np.array_equal(fast["option_distance"], whole["option_distance"])
        assert fast["length"] is None and whole["length"] > 0 or len(fast["firsts"]) == 1
        seen.append(len(fast["firsts"]))
        return fast

    monkeypatch.setattr(FrontierTour, "first_target_scores", both)
    planner = make_planner("guide", inpaint=oracle_inpainter(maze), candidates=2, num_inference_steps=2, **SINGLE_NODES)
    assert not layer(planner, TourVote).tour.tour_scores(2) and not layer(planner, TourVote).tour.tour_scores(10)
    result = run_episode(maze, planner, PROTOCOL)
    assert result.complete and len(seen) >= 5 and max(seen) >= 3
    assert innermost(make_planner("guide_tsp")).tour.tour_scores(10)  # guide_tsp's regret needs its whole tour
