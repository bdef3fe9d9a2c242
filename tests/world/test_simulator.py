from dataclasses import replace

import numpy as np
import pytest
from conftest import two_rooms

from pipeline.planners import make_planner, planner_config, planner_names
from pipeline.world.geometry import walk_cells
from pipeline.world.maps import GroundTruthMap, load_map
from pipeline.world.planner import Observation, Planner, Waypoint
from pipeline.world.protocol import PAPER_REAL_ROBOT, Protocol
from pipeline.world.sensor import FREE, OCCUPIED, UNKNOWN
from pipeline.world.simulator import Episode, MotionError, replay, run_episode
from pipeline.world.trajectories import read_trajectory_csv, write_trajectory_csv
from tests.conftest import write_ros_map


def test_waypoints_must_be_lattice_nodes(small_maze):
    episode = Episode(small_maze, Protocol())
    with pytest.raises(MotionError, match="lattice"):
        episode.move((2.0, 0.0))
    with pytest.raises(MotionError, match="outside"):
        episode.move((400.0, 0.0))


def test_moves_through_unknown_space_are_refused(small_maze):
    episode = Episode(small_maze, Protocol())
    # 40 m straight down from the start crosses walls and unknown cells.
    with pytest.raises(MotionError, match="not known to be free"):
        episode.move((0.0, 40.0))
    assert episode.steps == 0 and episode.distance == 0.0


# From the start (0, 0) of SMALL_MAZE the left corridor runs 20 m straight down, all of it free
# in the ground truth; the 20 m sensor has not seen its far end yet.
UNSENSED_CORRIDOR_END = (0.0, 20.0)


def test_moves_free_in_the_ground_truth_but_unsensed_need_the_oracle_rule(small_maze):
    """The motion rule checks the belief, not the ground truth; only `oracle=True` uses the latter."""
    episode = Episode(small_maze, Protocol())
    corridor = walk_cells(episode.cell, episode.waypoint_cell(UNSENSED_CORRIDOR_END)[0])
    assert small_maze.free[corridor[:, 1], corridor[:, 0]].all()  # no wall on the way
    assert (episode.belief.grid[corridor[:, 1], corridor[:, 0]] == UNKNOWN).any()  # not sensed yet
    with pytest.raises(MotionError, match="not known to be free"):
        episode.move(UNSENSED_CORRIDOR_END)
    assert episode.steps == 0 and episode.distance == 0.0
    episode.move(UNSENSED_CORRIDOR_END, oracle=True)
    assert episode.trajectory == [(0.0, 0.0), UNSENSED_CORRIDOR_END]
    assert episode.distance == pytest.approx(20.0)


def test_a_known_free_move_senses_and_counts_distance(small_maze):
    episode = Episode(small_maze, Protocol())
    before = episode.belief.free_count
    episode.move((4.0, 0.0))
    assert episode.distance == pytest.approx(4.0)
    assert episode.trajectory == [(0.0, 0.0), (4.0, 0.0)]
    assert episode.belief.free_count > before


def test_done_rule_uses_the_unknown_cell_count(small_maze):
    lenient = Episode(small_maze, Protocol(done_unknown_cells=small_maze.free_cell_count))
    assert lenient.complete and lenient.complete_after_waypoint == 1
    strict = Episode(small_maze, Protocol(done_unknown_cells=0))
    assert not strict.complete


def test_step_limit_ends_an_episode_as_failure(small_maze):
    result = run_episode(small_maze, make_planner("nearest_frontier"), Protocol(max_steps=3))
    assert not result.complete and result.steps == 3 and "step limit" in result.failure


@pytest.mark.parametrize("planner", ["nearest_frontier", "greedy_utility"])
def test_written_trajectory_replays_to_the_same_distance(small_maze, tmp_path, planner):
    result = run_episode(small_maze, make_planner(planner), Protocol())
    assert result.complete and result.motion_violations == 0
    path = write_trajectory_csv(tmp_path / "run.csv", result.trajectory)
    replayed = replay(small_maze, read_trajectory_csv(path), Protocol())
    assert replayed.complete
    assert replayed.distance_m == pytest.approx(result.distance_m, abs=1e-6)
    assert replayed.complete_after_waypoint == result.complete_after_waypoint == len(result.trajectory)


def test_replay_reports_a_motion_violation(small_maze):
    replayed = replay(small_maze, [(0, 0), (0, 40)], Protocol())
    assert not replayed.complete and replayed.motion_violations == 1


def test_replay_ignores_waypoints_after_completion(small_maze):
    """Legal rows after the done rule fired count for neither distance nor steps."""
    result = run_episode(small_maze, make_planner("nearest_frontier"), Protocol())
    assert result.complete and len(result.trajectory) >= 2
    last, before_last = result.trajectory[-1], result.trajectory[-2]
    padded = [*result.trajectory, before_last, last, before_last]  # known-free moves back and forth
    replayed = replay(small_maze, padded, Protocol())
    trimmed = replay(small_maze, result.trajectory, Protocol())
    assert replayed.complete and replayed.motion_violations == 0
    assert replayed.distance_m == pytest.approx(trimmed.distance_m, abs=1e-9)
    assert replayed.distance_m == pytest.approx(result.distance_m, abs=1e-6)
    assert replayed.steps == trimmed.steps == len(result.trajectory) - 1
    assert replayed.trajectory == trimmed.trajectory == result.trajectory


def test_replay_rejects_a_trajectory_without_its_start_row(small_maze):
    with pytest.raises(ValueError, match="at least its start row"):
        replay(small_maze, [], Protocol())
    # (4, 0) is a legal first move, so only the start-row check can refuse this trajectory.
    with pytest.raises(ValueError, match="first row must be the start"):
        replay(small_maze, [(4.0, 0.0), (8.0, 0.0)], Protocol())


class ScriptedPlanner(Planner):
    """Proposes fixed batches of waypoints, one batch per decision, then []."""

    name = "scripted"

    def __init__(self, batches: list[list[Waypoint]], ignores_motion_rule: bool = False):
        self.batches = batches
        self.ignores_motion_rule = ignores_motion_rule
        self.decisions = 0

    def reset(self, ground_truth: GroundTruthMap, protocol: Protocol, seed: int) -> None:
        self.decisions = 0

    def plan(self, observation: Observation) -> list[Waypoint]:
        self.decisions += 1
        return list(self.batches[self.decisions - 1]) if self.decisions <= len(self.batches) else []


def test_a_planner_breaking_the_motion_rule_fails_the_episode(small_maze):
    """The legal first waypoint counts; the one through walls stops the episode as a violation."""
    planner = ScriptedPlanner([[(4.0, 0.0), (0.0, 40.0), (8.0, 0.0)]])
    result = run_episode(small_maze, planner, Protocol())
    assert not result.complete and result.complete_after_waypoint is None
    assert result.motion_violations == 1
    assert result.failure.startswith("motion rule: ") and "not known to be free" in result.failure
    assert result.trajectory == [(0.0, 0.0), (4.0, 0.0)]
    assert result.steps == 1 and result.distance_m == pytest.approx(4.0)
    assert planner.decisions == 1 and len(result.decision_ms) == 1
    assert result.planner == "scripted"


def test_a_planner_with_nothing_to_propose_ends_the_episode_early(small_maze):
    planner = ScriptedPlanner([])
    result = run_episode(small_maze, planner, Protocol())
    assert not result.complete
    assert result.failure == "no reachable target left"
    assert result.motion_violations == 0
    assert result.steps == 0 and result.distance_m == 0.0 and result.trajectory == [(0.0, 0.0)]
    assert planner.decisions == 1 and len(result.decision_ms) == 1


def test_run_episode_applies_the_oracle_rule_only_to_planners_that_ignore_it(small_maze):
    """`ignores_motion_rule` lets a planner cross unsensed ground-truth-free space; others may not."""
    oracle = run_episode(small_maze, ScriptedPlanner([[UNSENSED_CORRIDOR_END]], ignores_motion_rule=True), Protocol())
    assert oracle.motion_violations == 0 and oracle.failure == "no reachable target left"
    assert oracle.trajectory == [(0.0, 0.0), UNSENSED_CORRIDOR_END]
    honest = run_episode(small_maze, ScriptedPlanner([[UNSENSED_CORRIDOR_END]]), Protocol())
    assert honest.motion_violations == 1 and honest.failure.startswith("motion rule: ")
    assert honest.trajectory == [(0.0, 0.0)]


def office_grid(resolution: float = 0.2) -> tuple[np.ndarray, tuple[float, float]]:
    """A 24 m x 14 m office: a corridor and six rooms behind 0.8 m doors in 0.2 m walls."""
    cells = lambda metres: int(round(metres / resolution))  # noqa: E731
    free = np.zeros((cells(14), cells(24)), dtype=bool)
    free[1:-1, 1:-1] = True
    corridor = (cells(5.8), cells(8.2))
    free[corridor[0] - 1, 1:-1] = False  # wall between the lower rooms and the corridor
    free[corridor[1], 1:-1] = False  # wall between the corridor and the upper rooms
    for x in (8.0, 16.0):  # walls between rooms
        free[1 : corridor[0] - 1, cells(x)] = False
        free[corridor[1] + 1 : -1, cells(x)] = False
    door = cells(0.8)
    for x0 in (3.1, 11.7, 18.3):  # doors off the lattice's columns, on purpose
        c = cells(x0)
        free[corridor[0] - 1, c : c + door] = True
        free[corridor[1], c + 2 : c + 2 + door] = True
    return free, (1.0, 7.0)


def test_real_robot_setting_explores_an_office_with_narrow_doors(tmp_path):
    free, start = office_grid()
    yaml_path = write_ros_map(tmp_path, free, 0.2, start)
    ground_truth = load_map(yaml_path)
    assert ground_truth.cell_size == 0.2
    protocol = replace(PAPER_REAL_ROBOT, done_unknown_cells=50)  # every room must be entered
    result = run_episode(ground_truth, make_planner("nearest_frontier"), protocol)
    assert result.complete, result.failure
    assert result.motion_violations == 0
    assert result.explored_ratio > 0.99


@pytest.mark.parametrize(
    "planner",
    [p for p in planner_names() if not planner_config(p).uses_ground_truth and not planner_config(p).needs_policy],
)
def test_every_planner_completes_generated_mazes(generated_maze_dir, planner):
    for path in sorted(generated_maze_dir.glob("*.png")):
        result = run_episode(load_map(path), make_planner(planner), Protocol())
        assert result.complete, f"{planner} on {path.name}: {result.failure}"
        assert result.motion_violations == 0


def test_resume_starts_from_a_given_belief_and_pose(small_maze):
    protocol = Protocol()
    episode = Episode(small_maze, protocol)
    episode.move((4.0, 0.0))
    observation = episode.observe()
    resumed = Episode.resume(small_maze, protocol, observation.belief, observation.cell, observation.position)
    assert resumed.distance == 0.0 and resumed.steps == 0 and not resumed.complete
    assert np.array_equal(resumed.belief.grid, episode.belief.grid) and resumed.belief.grid is not episode.belief.grid
    assert resumed.belief.free_count == episode.belief.free_count
    assert resumed.observe().changed.size == 0  # no first scan: nothing changed yet
    resumed.move((8.0, 0.0))
    episode.move((8.0, 0.0))
    assert resumed.distance == 4.0 and np.array_equal(resumed.belief.grid, episode.belief.grid)
    known = Episode.resume(
        small_maze,
        protocol,
        np.where(small_maze.free, FREE, OCCUPIED).astype(np.uint8),
        observation.cell,
        observation.position,
    )
    assert known.complete and known.completion_distance == 0.0  # a fully known map is explored already
    with pytest.raises(ValueError, match="differ in shape"):
        Episode.resume(small_maze, protocol, observation.belief[1:], observation.cell, observation.position)


def test_a_cell_centre_off_the_lattice_is_a_waypoint_only_under_the_door_graph():
    world = two_rooms()
    door = ((27 - world.start_cell[0]) * 0.2, (28 - world.start_cell[1]) * 0.2)  # the door's cell centre
    episode = Episode(world, PAPER_REAL_ROBOT)
    assert episode.waypoint_cell(door) == ((27, 28), pytest.approx(door))
    with pytest.raises(MotionError, match="a cell centre"):
        episode.waypoint_cell((door[0] + 0.05, door[1]))
    lattice = Episode(world, replace(PAPER_REAL_ROBOT, door_graph=False))
    with pytest.raises(MotionError, match="node lattice"):
        lattice.waypoint_cell(door)
