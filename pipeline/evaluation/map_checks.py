"""Checks of a user's map before and after episodes on it: what no planner can do there, and why.

Each check returns a one-line explanation, or None when the map is fine; the command line
prints them as warnings.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from pipeline.planners.references.coverage_model import unobservable_free_cells
from pipeline.world.maps import GroundTruthMap
from pipeline.world.protocol import Protocol
from pipeline.world.sensor import DEFAULT_ANGLES


def unreachable_free_cells(ground_truth: GroundTruthMap) -> int:
    """Free cells not 8-connected to the start: more than `done_unknown_cells` of them and no
    planner can complete the map (stray free pixels outside a SLAM map's walls do this)."""
    _, labels = cv2.connectedComponents(ground_truth.free.astype(np.uint8), connectivity=8)
    col, row = ground_truth.start_cell
    return int(ground_truth.free.sum() - (labels == labels[row, col]).sum())


def unreachable_problem(ground_truth: GroundTruthMap, protocol: Protocol) -> str | None:
    """Free cells beyond the start's reach outnumber the done rule's slack: the map can never complete."""
    cut_off = unreachable_free_cells(ground_truth)
    if cut_off <= protocol.done_unknown_cells:
        return None
    return (
        f"{ground_truth.name}: {cut_off} free cells are not connected to the start, more than "
        f"done_unknown_cells={protocol.done_unknown_cells}: no planner can complete this map "
        "(erase stray free pixels outside the walls, or raise --done-unknown-cells)"
    )


def fine_map_problem(ground_truth: GroundTruthMap, protocol: Protocol) -> str | None:
    """A map so fine that the lidar's neighbouring rays skip cells at full range explores badly
    (docs/cli.md, "Your own SLAM maps"): point at resample-map."""
    gap_cells = protocol.sensor_range * float(DEFAULT_ANGLES[1] - DEFAULT_ANGLES[0]) / ground_truth.cell_size
    if gap_cells <= 1.0:
        return None
    return (
        f"{ground_truth.name} is drawn at {ground_truth.cell_size:g} m per cell: the lidar's rays pass "
        f"{gap_cells:.1f} cells apart at {protocol.sensor_range:g} m and leave holes that read as frontier; "
        "`guide resample-map --map MAP --out OUT.yaml` writes it on the benchmark's 0.4 m grid"
    )


def unobservable_problem(ground_truth: GroundTruthMap, protocol: Protocol) -> str | None:
    """Scans on the ground truth from every reachable lattice node: a problem when the free cells none
    of them reveals outnumber the done rule's slack (a fine SLAM map's clutter and ragged walls do this)."""
    hidden = unobservable_free_cells(ground_truth, protocol)
    if hidden <= protocol.done_unknown_cells:
        return None
    return (
        f"{ground_truth.name}: {hidden} free cells are seen from no lattice node the robot can reach "
        f"(behind clutter, in nooks of the walls), more than done_unknown_cells={protocol.done_unknown_cells}: "
        f"no planner can complete this map (raise --done-unknown-cells above {hidden})"
    )


def step_limit_hint(ground_truth: GroundTruthMap, protocol: Protocol) -> str:
    """What to do when a map outgrows `max_steps` (500 waypoints suit the benchmark's 100 m mazes)."""
    rows, cols = ground_truth.free.shape
    side = max(rows, cols) * protocol.cell_size
    scale = max(1.0, (side / 100.0) ** 2)
    return (
        f"{ground_truth.name} is {cols * protocol.cell_size:.0f} m x {rows * protocol.cell_size:.0f} m; "
        f"--max-steps {protocol.max_steps} suits the benchmark's 100 m mazes: raise it with the map's area "
        f"(e.g. --max-steps {int(math.ceil(protocol.max_steps * scale / 100.0) * 100)})"
    )


def before_episodes(
    ground_truth: GroundTruthMap, protocol: Protocol, scan_for_unobservable: bool
) -> tuple[list[str], bool]:
    """(the problems worth saying before any episode runs on a map, whether it can be completed as
    far as the cheap checks tell). The ground-truth scans for unobservable cells run only when
    `scan_for_unobservable` (one map: worth it; a folder: only for the maps that then fail)."""
    problems = [p for p in (fine_map_problem(ground_truth, protocol),) if p]
    unreachable = unreachable_problem(ground_truth, protocol)
    if unreachable:
        problems.append(unreachable)
    elif scan_for_unobservable:
        problems += [p for p in (unobservable_problem(ground_truth, protocol),) if p]
    return problems, unreachable is None
