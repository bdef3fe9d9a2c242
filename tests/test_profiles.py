"""The paper profile is a complete params file: the same keys as the default, valid model configs."""

import pytest
import yaml
from import_graph import ROOT

from pipeline.models.configuration_diffusion import DiffusionPolicyConfig
from pipeline.models.configuration_inpainter import InpainterConfig
from pipeline.training.policy import PlannerTrainConfig

OPTION_MAPS = {"planner_options", "options"}  # a planner's options: any keys it takes


def key_paths(tree, prefix=()):
    if isinstance(tree, dict) and not (prefix and prefix[-1] in OPTION_MAPS):
        for key, value in tree.items():
            yield from key_paths(value, prefix + (key,))
    else:
        yield prefix


def test_paper_profile_has_the_default_keys_and_parses():
    default = yaml.safe_load((ROOT / "params.yaml").read_text())
    paper = yaml.safe_load((ROOT / "profiles" / "paper.yaml").read_text())
    assert set(key_paths(default)) == set(key_paths(paper))
    for params in (default, paper):
        DiffusionPolicyConfig.from_dict(params["train_planner"]["model"])
        PlannerTrainConfig.from_dict(params["train_planner"]["train"])
        InpainterConfig.from_dict(params["train_inpainter"]["model"])
        assert params["train_planner"]["model"]["max_nodes"] == params["build_observations"]["max_nodes"]
    assert paper["collect_expert"]["episodes"] == 4000
    # at least the paper's 10,000 Stage I pairs, and never less data than the default
    assert paper["collect_pairs"]["pairs"] >= max(10000, default["collect_pairs"]["pairs"])
    assert paper["mazes"]["train"]["count"] >= default["mazes"]["train"]["count"]
    assert paper["mazes"]["test"]["count"] == 100
    assert (
        DiffusionPolicyConfig.from_dict(paper["train_planner"]["model"]).d_model
        == DiffusionPolicyConfig.paper().d_model
    )


def test_every_profile_uses_the_planners_tau():
    """The benchmark's planners use node_predictor's two taus (graph nodes, utility count); the policy's
    training observations and Table I must see predictions at the same ones, or the policy is trained
    on another graph and Table I measures nodes the planners never hold."""
    from pipeline.planners.baselines.mapex import MapExPlanner
    from pipeline.planners.guide.guide_tsp import GuideTspPlanner
    from pipeline.prediction.node_predictor import DEFAULT_COUNT_THRESHOLD, DEFAULT_THRESHOLD, NodePredictorConfig

    assert DEFAULT_COUNT_THRESHOLD < DEFAULT_THRESHOLD
    assert NodePredictorConfig().threshold == DEFAULT_THRESHOLD
    assert NodePredictorConfig().count_threshold == DEFAULT_COUNT_THRESHOLD
    planner = GuideTspPlanner(inpaint=lambda image: image / 255.0)
    assert planner.predictor.config.threshold == DEFAULT_THRESHOLD
    assert planner.predictor.config.count_threshold == DEFAULT_COUNT_THRESHOLD
    mapex = MapExPlanner(inpaint=lambda image: image / 255.0)  # a predicted map, not graph nodes: the count's tau
    assert (
        mapex.predictor.config.threshold == DEFAULT_COUNT_THRESHOLD and mapex.predictor.config.count_threshold is None
    )
    for name in ("params.yaml", "profiles/paper.yaml"):
        params = yaml.safe_load((ROOT / name).read_text())
        assert params["build_observations"]["threshold"] == DEFAULT_THRESHOLD, name
        assert params["build_observations"]["count_threshold"] == DEFAULT_COUNT_THRESHOLD, name
        assert params["eval_predictor"]["threshold"] == DEFAULT_THRESHOLD, name


def test_real_robot_profile_has_the_default_keys_the_papers_scale_and_passes_every_stages_checks():
    import importlib

    from pipeline.stage_runner import read_protocol, read_stage
    from pipeline.world.protocol import PAPER_REAL_ROBOT, Protocol

    default = yaml.safe_load((ROOT / "params.yaml").read_text())
    path = ROOT / "profiles" / "real_robot.yaml"
    real = yaml.safe_load(path.read_text())
    assert set(key_paths(default)) == set(key_paths(real))
    protocol = Protocol.from_dict(real["protocol"])
    assert protocol == PAPER_REAL_ROBOT
    assert protocol.done_unknown_cells * protocol.cell_size**2 == pytest.approx(40.0)  # the 40 m^2 done rule
    assert real["mazes"]["train"]["kind"] == real["mazes"]["test"]["kind"] == "building"  # floors drawn like real plans
    assert real["train_planner"]["model"]["max_nodes"] == real["build_observations"]["max_nodes"]
    stages = {
        "benchmark": "benchmark",
        "build_observations": "build_observations",
        "collect_expert": "collect_expert",
        "collect_pairs": "collect_pairs",
        "distil_policy": "distil_policy",
        "eval_predictor": "eval_predictor",
        "fit_gate": "fit_gate",
        "generate_mazes": "mazes",
        "report": "report",
        "train_block_model": "train_block_model",
        "train_drl": "train_drl",
        "train_inpainter": "train_inpainter",
        "train_planner": "train_planner",
    }
    for module, section in stages.items():
        read_stage(path, section, importlib.import_module(f"stages.{module}").Settings)
    read_protocol(path)
