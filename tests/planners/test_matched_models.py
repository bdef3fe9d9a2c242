"""Learned planners take the default models trained at the protocol they run at (`ProtocolMatchedModels`)."""

from __future__ import annotations

import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from pipeline.models import defaults
from pipeline.models.defaults import MODEL_FILES, REAL_ROBOT_ASSETS, pick_model
from pipeline.models.sliver_gate import FEATURES, SliverGate, save_gate
from pipeline.planners.matched_models import ProtocolMatchedModels
from pipeline.planners.registry import make_planner
from pipeline.planners.wrapper import innermost
from pipeline.world.maps import GroundTruthMap
from pipeline.world.offices import OfficeConfig, draw_office
from pipeline.world.protocol import PAPER_REAL_ROBOT, Protocol, ProtocolMismatchWarning
from pipeline.world.simulator import run_episode

REAL = PAPER_REAL_ROBOT


def _gate(path: Path, protocol: Protocol, threshold: float) -> Path:
    """A gate file recording `protocol`; its threshold tells the files apart once loaded."""
    gate = SliverGate.logistic((0.0,) * len(FEATURES), 1.0, threshold=threshold)
    return save_gate(gate, path, protocol.to_dict())


@pytest.fixture
def gate_files(tmp_path, monkeypatch):
    """The gate catalogue pointed at three files: the pipeline's (maze scale), the shipped maze one
    and the shipped real-robot one."""
    monkeypatch.chdir(tmp_path)
    files = (
        _gate(tmp_path / "pipeline.json", Protocol(), 0.5),
        _gate(tmp_path / "maze.json", Protocol(), 0.6),
        _gate(tmp_path / "real.json", REAL, 0.7),
    )
    monkeypatch.setitem(MODEL_FILES, "gate", (files[0], files[1:]))
    return files


def test_pick_model_takes_the_first_trained_at_the_protocol_else_the_first(gate_files):
    pipeline, maze, real = gate_files
    assert pick_model("gate") == pipeline
    assert pick_model("gate", Protocol()) == pipeline
    assert pick_model("gate", REAL) == real
    assert pick_model("gate", replace(REAL, done_unknown_cells=250, cell_size=0.1)) == real  # not model inputs
    assert pick_model("gate", replace(REAL, sensor_range=12.0)) == pipeline  # none matches: the first
    pipeline.unlink()
    assert pick_model("gate") == maze


def _floor() -> GroundTruthMap:
    free, (row, col) = draw_office(OfficeConfig.real_robot(side_m=20.0), np.random.default_rng(4))
    return GroundTruthMap(free=free, start_cell=(col, row), cell_size=0.2, name="floor")


def test_a_gated_planner_switches_to_the_gate_of_the_protocol_at_reset(gate_files):
    pipeline, _, real = gate_files
    planner = make_planner("greedy_utility", sliver_gate=True)
    assert isinstance(planner, ProtocolMatchedModels)
    assert innermost(planner).gate.threshold == 0.5  # built before any protocol: the pipeline's
    result = run_episode(_floor(), planner, REAL, seed=0)
    assert result.complete
    assert planner.config.gate_file is None and innermost(planner).config.gate_file == str(real)
    assert innermost(planner).gate.threshold == 0.7
    planner.reset(_floor(), Protocol(cell_size=0.2), 0)  # back at the maze scale's model inputs
    assert innermost(planner).config.gate_file is None and innermost(planner).gate.threshold == 0.5


def test_a_named_model_is_never_replaced_and_injected_objects_are_not_wrapped(gate_files):
    pipeline, maze, _ = gate_files
    planner = make_planner("greedy_utility", sliver_gate=True, gate_file=str(maze))
    assert not isinstance(planner, ProtocolMatchedModels)
    planner.reset(_floor(), REAL, 0)
    assert innermost(planner).gate.threshold == 0.6
    assert not isinstance(make_planner("greedy_utility"), ProtocolMatchedModels)  # no trained model at all
    assert not isinstance(make_planner("guide_tsp", inpaint=lambda image: image / 255.0), ProtocolMatchedModels)


def test_the_shipped_real_robot_models_are_picked_at_that_scale_and_the_maze_ones_at_the_benchmarks(
    tmp_path, monkeypatch
):
    monkeypatch.chdir(tmp_path)  # no models/ here: only the shipped sets
    for kind in ("inpainter", "policy_guide", "gate"):
        assert MODEL_FILES[kind][1][1].parent == REAL_ROBOT_ASSETS and MODEL_FILES[kind][1][1].is_file()
    planner = make_planner("guide", candidates=2)
    with warnings.catch_warnings():
        warnings.simplefilter("error", ProtocolMismatchWarning)  # the real-robot models match: no warning
        result = run_episode(_floor(), planner, REAL, seed=0)
    assert result.complete
    assert Path(innermost(planner).config.policy_file) == REAL_ROBOT_ASSETS / "planner_guide.pt"
    assert Path(innermost(planner).config.inpainter_file) == REAL_ROBOT_ASSETS / "inpainter.pt"
    assert {Path(model) for model, _ in innermost(planner).trained_models} == {
        REAL_ROBOT_ASSETS / "planner_guide.pt",
        REAL_ROBOT_ASSETS / "inpainter.pt",
    }
    planner.reset(_floor(), Protocol(cell_size=0.2), 0)
    assert innermost(planner).config.policy_file is None  # the maze benchmark's protocol: the shipped maze models
    assert {Path(model) for model, _ in innermost(planner).trained_models} == {
        defaults.SHIPPED_POLICY["guide"],
        defaults.SHIPPED_INPAINTER,
    }


def test_a_protocol_no_model_was_trained_at_still_warns(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    planner = make_planner("guide_tsp")
    with pytest.warns(ProtocolMismatchWarning, match="trained at other protocol values"):
        planner.reset(_floor(), replace(REAL, node_resolution=2.0), 0)
    assert innermost(planner).config.inpainter_file is None  # the first default, as before
