"""The tour vote (`guide` in mode tour): the cycle guard keeps a swinging vote from walking the robot back and forth."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from pipeline.planners import make_planner
from pipeline.planners.extensions.tour_vote import TourVote
from pipeline.planners.wrapper import layer
from pipeline.world.maps import GroundTruthMap
from pipeline.world.protocol import Protocol
from pipeline.world.simulator import Episode
from tests.conftest import SINGLE_NODES

PROTOCOL = Protocol(sensor_range=16.0, utility_range=8.0, done_unknown_cells=20, max_steps=120)


def corridor() -> GroundTruthMap:
    """A straight corridor, 3 cells wide and 160 long (64 m at 0.4 m cells), started in the middle:
    a frontier at each end, equally far."""
    free = np.zeros((7, 164), dtype=bool)
    free[2:5, 2:162] = True
    return GroundTruthMap(free=free, start_cell=(82, 3), cell_size=0.4, name="corridor")


def swinging_guide(favoured: list[int]):
    """`guide` (nothing predicted, one executed step per decision) whose vote at decision i goes
    wholly to first-target option `favoured[i]`."""
    planner = make_planner(
        "guide",
        inpaint=lambda image: np.zeros(image.shape, np.float32),
        prior_weight=1000.0,
        candidates=2,
        num_inference_steps=2,
        action_steps=1,
        **SINGLE_NODES,
    )
    turn = [0]

    def votes(robot, paths, options):
        share = np.zeros(len(options["firsts"]))
        share[favoured[turn[0]] % len(share)] = 1.0
        turn[0] += 1
        return share

    layer(planner, TourVote).target_votes = votes
    return planner


def test_back_at_a_node_with_nothing_new_the_target_chosen_there_is_kept():
    ground_truth = corridor()
    planner = swinging_guide([0, 1, 1])
    planner.reset(ground_truth, PROTOCOL, 0)
    episode = Episode(ground_truth, PROTOCOL)
    first = episode.observe()
    planner.plan(first)
    chosen = planner.last_decision["target"]
    assert len(planner.last_decision["votes"]) >= 2  # two options: the vote decides between them
    quiet = replace(first, changed=np.zeros(0, dtype=np.int64))  # the same node, nothing seen since
    planner.plan(quiet)
    assert planner.last_decision["target"] == chosen  # the vote swung, the target chosen here is kept
    news = replace(first, changed=np.array([0]))  # something seen: the vote decides again, for the other option
    planner.plan(news)
    assert planner.last_decision["target"] != chosen
