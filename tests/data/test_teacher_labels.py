"""The teacher's labels: the shortest known path toward the node it heads for, at every state the driver reaches."""

import numpy as np
import pytest

from pipeline.data.teacher_labels import NoTargetError, TeacherLabelledDriver, path_label, teacher_target, unit_steps
from pipeline.planners import make_planner
from pipeline.planners.wrapper import innermost
from pipeline.prediction.graph_observation import expert_action_deltas
from pipeline.world.protocol import Protocol
from pipeline.world.simulator import run_episode

PROTOCOL = Protocol(max_steps=40)


def labelled_run(small_maze, driver=None, teacher="tare"):
    planner = TeacherLabelledDriver(make_planner(teacher), horizon=8, driver=driver)
    result = run_episode(small_maze, planner, PROTOCOL, seed=1)
    return planner, result


def test_every_decision_is_labelled_with_lattice_steps_toward_the_teachers_target(small_maze):
    planner, result = labelled_run(small_maze, driver=make_planner("nearest_frontier"))
    trajectory = np.asarray(result.trajectory)
    assert len(planner.labels) >= len(trajectory) - 1  # every state the robot moved from was labelled
    resolution = PROTOCOL.node_resolution
    for position, label in zip(trajectory, planner.labels):
        assert label.shape == (8, 2)
        steps = expert_action_deltas(position, label, resolution)  # within the policy's 5 x 5 window
        assert np.abs(steps).max() <= 2  # one lattice edge per step (edges span up to two nodes)
        moving = np.abs(steps).sum(axis=1) > 0
        assert not np.any(moving[1:] & ~moving[:-1])  # a label stops only at its target, then stays


def test_the_teacher_driving_follows_its_own_labels_and_another_driver_does_not_always(small_maze):
    teacher_driven, _ = labelled_run(small_maze)
    other, _ = labelled_run(small_maze, driver=make_planner("nearest_frontier"))
    moved = teacher_driven.agrees[:-1]
    assert np.mean(moved) > 0.9  # tare walks its own shortest path (a tie may pick another)
    assert np.mean(other.agrees[:-1]) < np.mean(moved)


def test_path_label_is_the_shortest_known_path_padded_by_staying(small_maze):
    planner, _ = labelled_run(small_maze)
    graph = innermost(planner.teacher).graph
    known = np.flatnonzero(np.isfinite(graph.shortest_paths(0)[0]))
    source, target = int(known[0]), int(known[-1])
    position = tuple(graph.node_world[source])
    label = path_label(graph, position, target, horizon=40)
    _, pred = graph.shortest_paths(source)
    path = graph.path_from_predecessors(pred, target)[1:]
    np.testing.assert_allclose(label[: len(path)], graph.node_world[path])
    np.testing.assert_allclose(label[len(path) :], np.repeat(graph.node_world[[target]], 40 - len(path), axis=0))
    staying = path_label(graph, position, None, horizon=3)
    np.testing.assert_allclose(staying, np.repeat(graph.node_world[[source]], 3, axis=0))


def test_a_planner_that_names_no_target_cannot_teach(small_maze):
    with pytest.raises(NoTargetError, match="nearest_frontier.*does not report"):
        labelled_run(small_maze, teacher="nearest_frontier")
    assert isinstance(NoTargetError("x"), ValueError)
    with pytest.raises(NoTargetError):
        teacher_target(make_planner("nearest_frontier"))


@pytest.mark.parametrize("options", [{}, {"sliver_gate": True}])
def test_greedy_utility_teaches_by_the_node_it_ranks_first(small_maze, options):
    planner = TeacherLabelledDriver(make_planner("greedy_utility", **options), horizon=8)
    result = run_episode(small_maze, planner, PROTOCOL, seed=1)
    assert len(planner.labels) >= len(result.trajectory) - 1
    assert np.mean(planner.agrees[:-1]) > 0.9  # greedy walks the shortest path to the node it names
    teacher = innermost(planner.teacher)
    assert teacher.last_decision == {} or teacher.last_decision["target"] in range(teacher.graph.node_count)


def test_straight_double_edges_are_split_into_unit_steps(small_maze):
    planner, _ = labelled_run(small_maze)
    graph = innermost(planner.teacher).graph
    doubles = [
        (a, b)
        for a in range(graph.node_count)
        for b in graph.neighbours(a)
        if np.abs(graph.node_ij[b] - graph.node_ij[a]).max() == 2
        and np.all((graph.node_ij[b] - graph.node_ij[a]) % 2 == 0)
    ]
    assert doubles  # the lattice's 5 x 5 window has them
    for a, b in doubles[:20]:
        split = unit_steps(graph, [int(a), int(b)])
        assert split[0] == a and split[-1] == b and len(split) in (2, 3)
        for u, v in zip(split[:-1], split[1:]):
            assert v in graph.neighbours(u)
        if len(split) == 3:
            np.testing.assert_array_equal(graph.node_ij[split[1]] * 2, graph.node_ij[a] + graph.node_ij[b])
    assert any(len(unit_steps(graph, [int(a), int(b)])) == 3 for a, b in doubles)
