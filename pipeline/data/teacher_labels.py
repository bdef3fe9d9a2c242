"""A teacher's labels for the states another planner drives into (DAgger's data, ours).

The teacher is any belief-only planner that names the lattice node it heads for
(`last_decision["target"]`): `guide`, `guide_tsp`, `mapex`, `tare`, `greedy_utility` (gated or
not) and `guide:lookahead=3`. At every state the driver reaches, the teacher plans from the same
observation, and its label is the first T_p nodes of the shortest known path from the robot's node
to that target: a function of the robot's belief alone, so a policy that sees the same belief can
learn it (the ground-truth expert's moves depend on a map the robot cannot see).

`TeacherLabelledDriver` is the planner the simulator runs: it asks the teacher, records the label,
and executes the driver's first waypoint (or the teacher's own, when the teacher drives).
"""

from __future__ import annotations

import numpy as np

from pipeline.lattice.graph import LatticeGraph
from pipeline.planners.wrapper import innermost
from pipeline.world.maps import MapFrame
from pipeline.world.planner import Observation, Planner, Waypoint
from pipeline.world.protocol import Protocol


class NoTargetError(ValueError):
    """The teacher planner does not say which node it heads for."""


def teacher_target(teacher: Planner) -> int:
    """The lattice node the teacher's last decision heads for."""
    decision = getattr(teacher, "last_decision", None) or {}
    if decision.get("target") is None:
        raise NoTargetError(
            f"planner {teacher.name!r} does not report the node it heads for (last_decision['target']); "
            "a teacher must: guide, guide_tsp, greedy_utility, mapex or tare (with their options)"
        )
    return int(decision["target"])


def unit_steps(graph: LatticeGraph, path: list[int]) -> list[int]:
    """The path with each straight two-node edge ((2, 0), (2, 2), ...) split at its middle node
    where both halves are known-free edges too.

    The two ways are equally short, so a shortest-path search takes either by the order it
    visits nodes, which no rotation of the map preserves; split, the label is the same whatever
    the search's order, and a policy trained with rotated copies sees one answer per state.
    """
    out = list(path[:1])
    for a, b in zip(path[:-1], path[1:]):
        step = graph.node_ij[b] - graph.node_ij[a]
        if np.abs(step).max() == 2 and np.all(step % 2 == 0):
            middle = graph.node_id(*(graph.node_ij[a] + step // 2))
            if middle >= 0 and middle in graph.neighbours(a) and b in graph.neighbours(middle):
                out.append(middle)
        out.append(b)
    return out


def path_label(graph: LatticeGraph, position: tuple[float, float], target: int | None, horizon: int) -> np.ndarray:
    """(horizon, 2) world waypoints: the first `horizon` nodes after the robot's on the shortest
    known path to `target` (in unit steps where they are as short, `unit_steps`), the last one
    repeated past its end (a stay, as Diffusion Policy pads its chunks); the robot's own position
    throughout when there is no target or no known path."""
    robot = graph.nearest_node(position)
    path: list[int] = []
    if target is not None and target != robot:
        _, predecessors = graph.shortest_paths(robot)
        path = unit_steps(graph, graph.path_from_predecessors(predecessors, target))
        path = path[1:] if len(path) > 1 and path[0] == robot else []
    points = graph.node_world[path[:horizon]] if path else np.asarray(graph.node_world[robot])[None]
    label = np.empty((horizon, 2), dtype=np.float32)
    label[: len(points)] = points
    label[len(points) :] = points[-1]
    return label


def follows(position: tuple[float, float], waypoint: tuple[float, float], label: np.ndarray) -> bool:
    """Whether a move to `waypoint` is the label's first step, or its first two as one straight
    double edge (the move `unit_steps` split)."""
    if np.allclose(waypoint, label[0], atol=1e-3):
        return True
    middle = (np.asarray(position) + np.asarray(waypoint)) / 2.0
    return len(label) > 1 and bool(
        np.allclose(middle, label[0], atol=1e-3) and np.allclose(waypoint, label[1], atol=1e-3)
    )


class TeacherLabelledDriver(Planner):
    """Runs `driver` (None: the teacher itself drives) and records, at every decision, the
    teacher's label (`labels`) and whether the executed waypoint is the label's first (`agrees`).

    One waypoint is executed per decision, so that every state the robot passes through is a
    labelled decision, as in the expert's episodes.
    """

    def __init__(self, teacher: Planner, horizon: int, driver: Planner | None = None) -> None:
        self.teacher, self.driver, self.horizon = teacher, driver, int(horizon)
        self.name = f"{(driver or teacher).name} labelled by {teacher.name}"
        self.labels: list[np.ndarray] = []
        self.agrees: list[bool] = []

    def reset(self, frame: MapFrame, protocol: Protocol, seed: int) -> None:
        self.teacher.reset(frame, protocol, seed)
        if self.driver is not None:
            self.driver.reset(frame, protocol, seed + 1)  # the driver's draws apart from the teacher's
        self.labels, self.agrees = [], []

    def plan(self, observation: Observation) -> list[Waypoint]:
        taught = self.teacher.plan(observation)
        target = teacher_target(self.teacher) if taught else None
        graph = innermost(self.teacher).graph  # type: ignore[attr-defined]  # every teacher is a lattice-graph planner
        label = path_label(graph, observation.position, target, self.horizon)
        waypoints = taught if self.driver is None else self.driver.plan(observation)
        waypoints = list(waypoints[:1])
        self.labels.append(label)
        self.agrees.append(bool(waypoints) and follows(observation.position, waypoints[0], label))
        return waypoints
