"""The trust a predicting planner puts in its predictions (extensions/prediction_trust.py), in episodes."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.planners import make_planner
from pipeline.planners.wrapper import innermost
from pipeline.prediction.node_image import ground_truth_states, node_states_image
from pipeline.prediction.node_predictor import pad_to_multiple
from pipeline.world.building_config import BuildingConfig
from pipeline.world.buildings import generate_building_set
from pipeline.world.maps import load_maze_png
from pipeline.world.protocol import PAPER_REAL_ROBOT
from pipeline.world.simulator import run_episode


@pytest.fixture(scope="module")
def building(tmp_path_factory):
    path = generate_building_set(
        BuildingConfig(side_m=24.0), 1, tmp_path_factory.mktemp("b"), seed=[5], progress=False
    )[0]
    return load_maze_png(path, cell_size=0.2)


def oracle_for(ground_truth, wrong: bool = False):
    """An inpainter that knows the ground truth: each image answered from the node states it
    shows, free where the truth is free (or, `wrong`, exactly where it is not)."""

    def inpaint(image: np.ndarray) -> np.ndarray:
        planner = innermost(holder["planner"])
        truth = node_states_image(planner.graph, ground_truth_states(planner.graph, ground_truth.free))
        padded, _ = pad_to_multiple(truth, 8, 255 if wrong else 0)
        answer = (padded == 0) if wrong else (padded == 255)
        return answer.astype(np.float32) if padded.shape == image.shape else np.zeros(image.shape, np.float32)

    holder: dict = {}
    return inpaint, holder


def test_a_planner_trusts_an_inpainter_that_is_right_and_drops_one_that_is_wrong(building):
    inpaint, holder = oracle_for(building)
    right = make_planner("guide_tsp", inpaint=inpaint)
    holder["planner"] = right
    result = run_episode(building, right, PAPER_REAL_ROBOT, seed=0)
    assert result.complete
    assert right.trust_state.lift > 0.5 and min(t for t in result.waypoint_trust[1:]) == 1.0

    inpaint, holder = oracle_for(building, wrong=True)
    wrong = make_planner("guide_tsp", inpaint=inpaint, min_component=0)
    holder["planner"] = wrong
    result = run_episode(building, wrong, PAPER_REAL_ROBOT, seed=0)
    state = wrong.trust_state
    assert result.complete and state.wrong > state.right
    assert state.lift < -0.2 and result.waypoint_trust[-1] == 0.0
    rows = result.step_rows()
    assert rows[0]["prediction_trust"] is None and rows[-1]["prediction_trust"] == 0.0
    # At trust 0 the planner plans on the observed graph alone: nothing predicted enters.
    assert innermost(wrong).predict().size == 0

    untrusting = make_planner("guide_tsp", inpaint=lambda image: np.ones(image.shape, np.float32), trust=False)
    result = run_episode(building, untrusting, PAPER_REAL_ROBOT, seed=0)
    assert all(t is None for t in result.waypoint_trust) and getattr(untrusting, "trust_state", None) is None


def test_calling_everything_free_is_the_base_rate_kept_by_default_and_cut_by_a_stricter_setting(building):
    everything_free = lambda image: np.ones(image.shape, np.float32)  # noqa: E731
    default = make_planner("guide_tsp", inpaint=everything_free)
    run_episode(building, default, PAPER_REAL_ROBOT, seed=0)
    assert abs(default.trust_state.lift) < 0.15 and default.prediction_trust > 0.2
    strict = make_planner("guide_tsp", inpaint=everything_free, trust_none=0.2, trust_full=0.5)
    result = run_episode(building, strict, PAPER_REAL_ROBOT, seed=0)
    assert result.waypoint_trust[-1] == 0.0


def test_trust_settings_are_checked():
    with pytest.raises(ValueError, match="trust_none"):
        make_planner("guide_tsp", trust_none=0.5, trust_full=0.3)
    assert make_planner("greedy_utility").prediction_trust is None
