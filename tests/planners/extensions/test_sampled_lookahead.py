"""sampled_lookahead: rollouts on drawn maps, never on the ground truth."""

from __future__ import annotations

import os

import numpy as np
import pytest

from pipeline.models.configuration_block_model import BlockModelConfig
from pipeline.models.defaults import SHIPPED_BLOCK_MODEL, resolve_block_model
from pipeline.models.modeling_block_model import BlockModel, save_block_model
from pipeline.planners import make_planner, planner_config
from pipeline.planners.wrapper import innermost
from pipeline.prediction.block_maps import block_index, true_blocks
from pipeline.world.maps import GroundTruthMap
from pipeline.world.protocol import Protocol
from pipeline.world.simulator import Episode, run_episode


class KnownBlocks(BlockModel):
    """A block model that answers fixed probabilities (the truth, or a coin) whatever it sees."""

    def __init__(self, probability: np.ndarray):
        super().__init__(BlockModelConfig(width=4, dilations=(1,), groups=1))
        self.probability = probability

    def free_probability(self, shares: np.ndarray, temperature: float = 1.0) -> np.ndarray:
        assert shares.shape[-2:] == self.probability.shape
        return self.probability


def _truth(maze) -> np.ndarray:
    blocks, grid = block_index(maze.shape, maze.cell_size, 5.0)
    return true_blocks(maze.free, blocks, grid).astype(np.float32)


def test_k1_is_gated_greedy(small_maze):
    protocol = Protocol()
    gated = run_episode(small_maze, make_planner("greedy_utility", sliver_gate=True), protocol, 0)
    one = run_episode(
        small_maze, make_planner("sampled_lookahead", k=1, model=KnownBlocks(_truth(small_maze))), protocol, 0
    )
    assert one.trajectory == gated.trajectory and one.complete


def test_explores_without_reading_the_ground_truth(small_maze):
    """The same decisions when reset() gets a map whose cells are all wall: only its size is read."""
    protocol = Protocol()
    model = KnownBlocks(np.where(_truth(small_maze) > 0, 0.9, 0.1).astype(np.float32))  # draws differ, seeded
    blind = GroundTruthMap(np.zeros_like(small_maze.free), small_maze.start_cell, small_maze.cell_size)
    runs = []
    for reset_map in (small_maze, blind):
        planner = make_planner("sampled_lookahead", k=2, samples=1, model=model)
        planner.reset(reset_map, protocol, 3)
        episode = Episode(small_maze, protocol)
        while not episode.complete and episode.steps < 60:
            episode.move(planner.plan(episode.observe())[0])
        runs.append(episode.trajectory)
    assert runs[0] == runs[1] and not planner_config("sampled_lookahead").uses_ground_truth
    assert episode.complete


def test_a_true_block_map_makes_it_no_longer_than_gated_greedy(small_maze):
    protocol = Protocol()
    gated = run_episode(small_maze, make_planner("greedy_utility", sliver_gate=True), protocol, 0)
    looked = run_episode(
        small_maze,
        make_planner("sampled_lookahead", samples=1, horizon_m=100.0, model=KnownBlocks(_truth(small_maze))),
        protocol,
        0,
    )
    assert looked.complete and looked.motion_violations == 0
    assert looked.distance_m <= gated.distance_m


def test_model_file_resolution(tmp_path):
    with pytest.raises(ValueError, match="expected a block model file"):
        make_planner("sampled_lookahead", block_model_file=str(tmp_path / "missing.pt"))
    path = save_block_model(BlockModel(BlockModelConfig(width=4, dilations=(1,), groups=1)), tmp_path / "b.pt")
    planner = make_planner("sampled_lookahead", block_model_file=str(path))
    assert innermost(planner).model.config.width == 4 and str(path) in innermost(planner).model_source
    assert str(path) in planner.description and "sliver gate (shipped)" in planner.description
    assert resolve_block_model(None) == SHIPPED_BLOCK_MODEL  # no models/ in tests: the shipped one
    with pytest.raises(ValueError, match="samples"):
        make_planner("sampled_lookahead", samples=0, block_model_file=str(path))


def test_switch_margin_keeps_the_last_target_unless_beaten_by_more(small_maze, monkeypatch):
    """Scripted rollouts: the last target costs 10 m a map, any other 9 m. Without a margin the robot
    switches; with a 2 m margin it keeps its target; a 0.5 m margin is beaten."""
    from pipeline.planners.extensions.lookahead import BlockLookahead

    protocol = Protocol()
    model = KnownBlocks(_truth(small_maze))
    chosen = {}

    def decide(margin):
        planner = make_planner("sampled_lookahead", k=3, samples=2, switch_margin_m=margin, model=model)
        planner.reset(small_maze, protocol, 0)
        episode = Episode(small_maze, protocol)
        observation = episode.observe()
        _, ranked = innermost(planner).ranked_targets(observation)
        assert ranked.size >= 2
        innermost(planner).last_target = int(ranked[1])
        monkeypatch.setattr(
            BlockLookahead,
            "rollout",
            staticmethod(lambda trial, ep, target, pred, per_target=False: 10.0 if target == int(ranked[1]) else 9.0),
        )
        planner.plan(observation)
        monkeypatch.undo()
        chosen[margin] = innermost(planner).last_target == int(ranked[1])

    for margin in (None, 2.0, 0.5):
        decide(margin)
    assert chosen == {None: False, 2.0: True, 0.5: False}


def test_exit_weight_prefers_the_rollout_that_ends_nearer_the_cut(small_maze, monkeypatch):
    """Scripted rollouts of equal length: the first-ranked target's ends 20 cells from the cut, the
    second's beside it. Without the exit term the tie goes to the first; with it, to the second."""
    import pipeline.planners.extensions.lookahead as module

    protocol = Protocol()
    model = KnownBlocks(_truth(small_maze))

    def decide(exit_weight):
        planner = make_planner("sampled_lookahead", k=2, samples=2, exit_weight=exit_weight, model=model)
        planner.reset(small_maze, protocol, 0)
        observation = Episode(small_maze, protocol).observe()
        _, ranked = innermost(planner).ranked_targets(observation)
        assert ranked.size >= 2

        def rollout(trial, episode, target, pred, per_target=False):
            episode.cell = (0, 0) if target == int(ranked[1]) else (0, 20)
            return 10.0

        monkeypatch.setattr(module.BlockLookahead, "rollout", staticmethod(rollout))
        monkeypatch.setattr(
            module,
            "exit_steps",
            lambda world, imagined: np.tile(np.arange(world.shape[1], dtype=np.float32), (world.shape[0], 1)),
        )
        planner.plan(observation)
        monkeypatch.undo()
        return innermost(planner).last_target == int(ranked[1])

    assert not decide(0.0) and decide(1.0)


def _guide(**options):
    from pipeline.models.defaults import SHIPPED_POLICY

    blank = lambda image: np.zeros(np.shape(image), np.float32)  # noqa: E731
    return make_planner(
        "guide", policy_file=str(SHIPPED_POLICY["guide"]), inpaint=blank, num_inference_steps=3, **options
    )


@pytest.mark.parametrize("targets", ["greedy", "tour"])
def test_guide_lookahead_takes_the_target_whose_rollouts_are_shortest(small_maze, monkeypatch, targets):
    """Scripted rollouts: equal costs keep guide's own choice (the first candidate: its best-scored
    option); making the last candidate's rollouts shorter makes it the target."""
    from pipeline.planners.extensions.lookahead import BlockLookahead

    protocol = Protocol()
    seen: list[int] = []
    order: list[int] = []  # the candidates in guide's order (rollouts may run in another: greedy's start first)
    finish = BlockLookahead.finish

    def recording_finish(self, rollouts, candidates):
        order[:] = candidates
        return finish(self, rollouts, candidates)

    def decide(cheap: int | None) -> dict:
        planner = _guide(
            lookahead=3, lookahead_samples=2, lookahead_targets=targets, block_model_file=str(SHIPPED_BLOCK_MODEL)
        )
        planner.reset(small_maze, protocol, 0)
        observation = Episode(small_maze, protocol).observe()

        def rollout(trial, episode, target, pred, per_target=False):
            assert trial is not planner and trial.graph is not innermost(planner).graph  # a copy, not guide itself
            seen.append(target)
            return 5.0 if target == cheap else 10.0

        monkeypatch.setattr(BlockLookahead, "rollout", staticmethod(rollout))
        monkeypatch.setattr(BlockLookahead, "finish", recording_finish)
        planner.plan(observation)
        monkeypatch.undo()
        return planner.last_decision

    plain = _guide()
    plain.reset(small_maze, protocol, 0)
    plain.plan(Episode(small_maze, protocol).observe())
    tied = decide(None)
    candidates = list(order)
    assert set(seen) == set(candidates)
    # guide's choice and greedy's best 3, or guide's best 3 options; each on 2 drawn maps
    assert 2 <= len(candidates) <= (4 if targets == "greedy" else 3) and len(seen) == 2 * len(candidates)
    assert tied["target"] == plain.last_decision["target"] == candidates[0]
    assert list(tied["lookahead_costs"]) == [10.0] * len(candidates)
    assert decide(candidates[-1])["target"] == candidates[-1]


def test_guide_lookahead_explores_a_maze(small_maze):
    result = run_episode(small_maze, _guide(lookahead=2, lookahead_samples=1), Protocol(), 0)
    assert result.complete and result.motion_violations == 0


def test_guide_lookahead_options_are_checked():
    with pytest.raises(ValueError, match="lookahead: must be 0"):
        _guide(lookahead=1)
    with pytest.raises(ValueError, match="in mode policy"):
        _guide(lookahead=3, mode="policy")
    with pytest.raises(ValueError, match="lookahead is off"):
        _guide(block_model_file="x.pt")
    with pytest.raises(ValueError, match="lookahead is off"):
        _guide(lookahead_commit=False)
    with pytest.raises(ValueError, match="samples"):
        _guide(lookahead=3, lookahead_samples=0)
    with pytest.raises(ValueError, match="lookahead_targets: must be one of 'greedy', 'tour'"):
        _guide(lookahead=3, lookahead_targets="best")
    assert "lookahead 3 x 4 maps, full rollouts, block model (shipped)" in _guide(lookahead=3).description


def test_guide_lookahead_keeps_its_target_until_reached_unless_told_not_to(small_maze, monkeypatch):
    """With lookahead_commit (the default) the rollouts run only when the last target is reached or
    is no longer a target; in between each decision keeps it. Without, every sampled decision rolls out."""
    from pipeline.planners.extensions.lookahead import BlockLookahead

    protocol = Protocol()
    calls: list[int] = []
    monkeypatch.setattr(
        BlockLookahead,
        "rollout",
        staticmethod(lambda trial, ep, target, pred, per_target=False: calls.append(target) or 10.0),
    )
    rounds = {}
    for commit in (None, False):
        # guide_tsp's clusters as the tour's options: their targets lie a few steps away, so a kept one is not
        # reached at every decision (a single-node target next to the robot often is)
        planner = _guide(
            lookahead=2,
            lookahead_samples=1,
            spread=None,
            min_weight=30.0,
            **({} if commit is None else {"lookahead_commit": commit}),
        )
        planner.reset(small_maze, protocol, 0)
        episode = Episode(small_maze, protocol)
        decisions = []  # (rolled out, target)
        for _ in range(10):
            before = len(calls)
            episode.move(planner.plan(episode.observe())[0])
            if planner.last_decision.get("sampled"):
                decisions.append((len(calls) > before, planner.last_decision["target"]))
        rounds[commit] = sum(rolled for rolled, _ in decisions)
        if commit is None:
            for (_, previous), (rolled, target) in zip(decisions, decisions[1:]):
                assert rolled or target == previous
    assert 1 <= rounds[None] < rounds[False]


def test_per_target_rollouts_choose_only_on_arrival(small_maze):
    """`finish_episode(per_target=True)` walks each chosen target's whole path before choosing again:
    every choice after the first is made standing on the last target, and there are no more of them
    than when greedy chooses at every node. Both finish the maze."""
    import copy

    from pipeline.planners.baselines.frontier import GreedyUtilityPlanner

    protocol = Protocol()
    base = make_planner("greedy_utility")
    base.reset(small_maze, protocol, 0)
    start = Episode(small_maze, protocol)
    pred, ranked = innermost(base).ranked_targets(start.observe())
    results, updates = {}, {}
    for per_target in (False, True):
        planner, episode = copy.deepcopy(base), copy.deepcopy(start)
        choices = []  # (robot node when choosing, the target it then walks to)
        ranked_targets, update_graph = innermost(planner).ranked_targets, innermost(planner).update_graph
        count = [0]  # graph updates: one per choice, whichever way the rollout ranks its targets

        def counting(observation, ranked_targets=ranked_targets, planner=planner, choices=choices):
            pred, ranked = ranked_targets(observation)
            choices.append((innermost(planner).robot, int(ranked[0]) if ranked.size else None))
            return pred, ranked

        def updating(observation, update_graph=update_graph, count=count):
            count[0] += 1
            return update_graph(observation)

        innermost(planner).ranked_targets, innermost(planner).update_graph = counting, updating
        distance = GreedyUtilityPlanner.finish_episode(innermost(planner), episode, int(ranked[0]), pred, per_target)
        assert distance is not None and np.isfinite(distance) and episode.complete
        results[per_target], updates[per_target] = choices, count[0]
    walked = [(None, int(ranked[0]))] + results[True]
    assert all(robot == target for (_, target), (robot, _) in zip(walked, walked[1:]))
    assert updates[True] == len(results[True]) <= updates[False]


@pytest.mark.parametrize("rollout", [None, "fast", "full"])
def test_guide_lookahead_rollout_kinds(small_maze, monkeypatch, rollout):
    """Full rollouts (the default): gated greedy choosing at every node; fast: ungated greedy walking whole paths."""
    from pipeline.planners.extensions.lookahead import BlockLookahead

    seen = []
    monkeypatch.setattr(
        BlockLookahead,
        "rollout",
        staticmethod(
            lambda trial, ep, target, pred, per_target=False: seen.append((trial.gate is None, per_target)) or 10.0
        ),
    )
    planner = _guide(
        lookahead=3,
        lookahead_samples=1,
        sliver_gate=True,
        **({} if rollout is None else {"lookahead_rollout": rollout}),
    )
    assert innermost(planner).gate is not None
    planner.reset(small_maze, Protocol(), 0)
    planner.plan(Episode(small_maze, Protocol()).observe())
    fast = rollout == "fast"
    assert seen and set(seen) == {(fast, fast)}
    assert innermost(planner).gate is not None  # guide's own gate is untouched


def test_guide_lookahead_rollout_option_is_checked():
    with pytest.raises(ValueError, match="lookahead_rollout: must be one of 'full', 'fast'"):
        _guide(lookahead=3, lookahead_rollout="quick")
    with pytest.raises(ValueError, match="lookahead is off"):
        _guide(lookahead_rollout="fast")


def _lookahead_decision(small_maze, workers: int, steps: int = 6):
    """A gated greedy planner a few steps into the small maze, and a lookahead with `workers` processes on it."""
    from pipeline.planners.extensions.lookahead import BlockLookahead, gated_greedy_like

    protocol = Protocol()
    planner = make_planner("greedy_utility", sliver_gate=True)
    planner.reset(small_maze, protocol, 0)
    episode = Episode(small_maze, protocol)
    for _ in range(steps):
        episode.move(planner.plan(episode.observe())[0])
    observation = episode.observe()
    pred, ranked = innermost(planner).ranked_targets(observation)
    lookahead = BlockLookahead(
        KnownBlocks(np.where(_truth(small_maze) > 0, 0.8, 0.2).astype(np.float32)), samples=3, workers=workers
    )
    lookahead.reset(small_maze)
    return lookahead, gated_greedy_like(innermost(planner)), observation, [int(t) for t in ranked[:4]], pred


def test_a_second_process_gives_the_same_rollout_costs(small_maze):
    """Two processes share one decision's rollouts, also a batch added after the start (guide's own
    target, known only after its denoising), and find the costs one process finds, to the bit."""
    alone, planner, observation, candidates, pred = _lookahead_decision(small_maze, workers=1)
    assert len(candidates) >= 3
    want = alone.costs(planner, observation, candidates, pred, np.random.default_rng(5))
    paired = _lookahead_decision(small_maze, workers=2)[0]
    try:
        for first in (candidates, candidates[1:]):  # everything at the start, then one candidate added at the end
            rollouts = paired.start(planner, observation, first, pred, np.random.default_rng(5))
            assert rollouts.remote
            np.testing.assert_array_equal(paired.finish(rollouts, candidates), want)
        worker = paired._worker
        assert worker is not None and worker.pid != os.getpid()
    finally:
        paired.close()
    assert paired._worker is None


def test_a_dead_worker_leaves_the_rollouts_to_the_planner(small_maze):
    """A worker killed from outside: the planner runs its share itself (the same costs) and forks another next time."""
    import signal

    alone, planner, observation, candidates, pred = _lookahead_decision(small_maze, workers=1)
    want = alone.costs(planner, observation, candidates, pred, np.random.default_rng(2))
    paired = _lookahead_decision(small_maze, workers=2)[0]
    try:
        paired.costs(planner, observation, candidates, pred, np.random.default_rng(2))
        first = paired._worker.pid
        os.kill(first, signal.SIGKILL)
        os.waitpid(first, 0)
        np.testing.assert_array_equal(
            paired.costs(planner, observation, candidates, pred, np.random.default_rng(2)), want
        )
        np.testing.assert_array_equal(
            paired.costs(planner, observation, candidates, pred, np.random.default_rng(2)), want
        )
        assert paired._worker is not None and paired._worker.pid != first
    finally:
        paired.close()


def test_copies_of_a_lookahead_leave_its_worker_behind(small_maze):
    import copy
    import pickle

    paired, planner, observation, candidates, pred = _lookahead_decision(small_maze, workers=2)
    try:
        paired.costs(planner, observation, candidates, pred, np.random.default_rng(0))
        assert paired._worker is not None
        assert copy.deepcopy(paired)._worker is None and pickle.loads(pickle.dumps(paired))._worker is None
    finally:
        paired.close()


def test_guide_with_two_lookahead_processes_takes_the_same_route(small_maze):
    routes = [
        run_episode(small_maze, _guide(lookahead=2, lookahead_samples=2, lookahead_workers=workers), Protocol(), 0)
        for workers in (1, 2)
    ]
    assert routes[0].trajectory == routes[1].trajectory and routes[1].complete
    with pytest.raises(ValueError, match=r"workers: must be a whole number in 1\.\.2"):
        _guide(lookahead=3, lookahead_workers=3)
    with pytest.raises(ValueError, match="lookahead is off"):
        _guide(lookahead_workers=2)
    assert "full rollouts in 2 processes" in _guide(lookahead=3, lookahead_workers=2).description
    with pytest.raises(ValueError, match=r"workers: must be a whole number in 1\.\.2"):
        make_planner("sampled_lookahead", workers=0, model=KnownBlocks(_truth(small_maze)))


def test_a_decision_that_never_collects_its_rollouts_leaves_no_stale_answer(small_maze):
    """A decision that fails between `start` and `finish` (its worker batch never received): the next
    decision still gets its own costs, not the abandoned batch's."""
    alone, planner, observation, candidates, pred = _lookahead_decision(small_maze, workers=1)
    want = alone.costs(planner, observation, candidates[:2], pred, np.random.default_rng(9))
    paired = _lookahead_decision(small_maze, workers=2)[0]
    try:
        paired.start(planner, observation, candidates, pred, np.random.default_rng(1))  # abandoned
        np.testing.assert_array_equal(
            paired.costs(planner, observation, candidates[:2], pred, np.random.default_rng(9)), want
        )
    finally:
        paired.close()
