"""A stage's params file: parsed into sections, or one error naming the file."""

from __future__ import annotations

import pytest

from pipeline.models.configuration_diffusion import DiffusionPolicyConfig
from pipeline.common.params import dataclass_from_dict, load_params, params_section, complete_section
from pipeline.world.protocol import Protocol
from pipeline.training.policy import PlannerTrainConfig


def test_load_params_reads_sections_and_names_the_file_when_it_cannot(tmp_path):
    good = tmp_path / "params.yaml"
    good.write_text("mazes:\n  seed: 3\nprotocol: {}\n")
    params = load_params(good)
    assert params == {"mazes": {"seed": 3}, "protocol": {}}
    assert params_section(params, "mazes", good) == {"seed": 3}
    empty = tmp_path / "empty.yaml"
    empty.write_text("")
    assert load_params(empty) == {}
    with pytest.raises(FileNotFoundError, match="nope.yaml: params file not found"):
        load_params(tmp_path / "nope.yaml")
    with pytest.raises(FileNotFoundError, match="not a file"):
        load_params(tmp_path)
    markdown = tmp_path / "README.md"
    markdown.write_text("# guide\n\n*GUIDE: a paper*\n")  # '*' starts a YAML alias
    with pytest.raises(ValueError, match=r"README.md: not valid YAML \(.* at line 3, column 1\)"):
        load_params(markdown)
    listed = tmp_path / "list.yaml"
    listed.write_text("- mazes\n- benchmark\n")
    with pytest.raises(ValueError, match="list.yaml: a params file is a YAML mapping of sections .*not a list"):
        load_params(listed)
    binary = tmp_path / "model.pt"
    binary.write_bytes(b"\x80\x04\x95\xff\xfe")
    with pytest.raises(ValueError, match="model.pt: not a params file"):
        load_params(binary)


def test_params_section_names_a_missing_or_malformed_section(tmp_path):
    path = tmp_path / "params.yaml"
    with pytest.raises(ValueError, match=r"params.yaml: missing the 'collect_expert' section"):
        params_section({"protocol": {}}, "collect_expert", path)
    with pytest.raises(ValueError, match=r"the 'mazes' section must be a mapping of settings, got \[1, 2\]"):
        params_section({"mazes": [1, 2]}, "mazes", path)


def test_dataclass_from_dict_builds_the_config_and_refuses_a_typo():
    assert dataclass_from_dict(PlannerTrainConfig, {"max_epochs": 3}, "planner training keys").max_epochs == 3
    assert dataclass_from_dict(Protocol, None, "protocol parameter(s):") == Protocol()
    with pytest.raises(ValueError, match=r"unknown planner training keys \['max_epoch'\]; known: \[.*'max_epochs'"):
        PlannerTrainConfig.from_dict({"max_epoch": 3})
    with pytest.raises(ValueError, match=r"unknown diffusion policy config keys \['heeds'\]"):
        DiffusionPolicyConfig.from_dict({"heeds": 2})


def test_complete_section_needs_every_key_and_refuses_a_typo():
    keys = ("epochs", "lr")
    assert complete_section({"s": {"epochs": 2, "lr": 0.1}}, "s", "p.yaml", keys) == {"epochs": 2, "lr": 0.1}
    with pytest.raises(ValueError, match=r"p.yaml: unknown s parameter\(s\) \['epoch'\]; known: \['epochs', 'lr'\]"):
        complete_section({"s": {"epoch": 2, "lr": 0.1}}, "s", "p.yaml", keys)
    with pytest.raises(ValueError, match=r"p.yaml: the 's' section misses \['lr'\]"):
        complete_section({"s": {"epochs": 2}}, "s", "p.yaml", keys)
    with pytest.raises(ValueError, match="missing the 's' section"):
        complete_section({}, "s", "p.yaml", keys)
