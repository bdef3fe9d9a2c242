"""A stage's params file: parsed into sections, or one error naming the file."""

from __future__ import annotations

import pytest

from pipeline.common.params import load_params, params_section
from pipeline.models.configuration_diffusion import DiffusionPolicyConfig
from pipeline.training.policy import PlannerTrainConfig
from pipeline.world.protocol import Protocol


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


def test_a_config_from_a_mapping_refuses_a_typo_by_its_dotted_key():
    assert PlannerTrainConfig.from_dict({"max_epochs": 3}).max_epochs == 3
    assert Protocol.from_dict(None) == Protocol()
    with pytest.raises(ValueError, match=r"^train\.max_epoch: unknown setting \(known: max_epochs, .*\), got 3$"):
        PlannerTrainConfig.from_dict({"max_epoch": 3})
    with pytest.raises(ValueError, match=r"^model\.heeds: unknown setting \(known: .*heads.*\), got 2$"):
        DiffusionPolicyConfig.from_dict({"heeds": 2})
