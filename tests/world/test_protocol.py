"""The protocol object: its checks, and which of its values a trained model depends on."""

from __future__ import annotations

import pytest

from pipeline.world.protocol import MODEL_INPUT_FIELDS, Protocol, model_input_differences


def test_bad_values_are_refused_with_the_parameter_named():
    with pytest.raises(ValueError, match=r"^Protocol: sensor_range: must be a finite number > 0 \(metres\), got nan$"):
        Protocol(sensor_range=float("nan"))
    with pytest.raises(ValueError, match=r"^protocol\.sensor_range: must be a finite number > 0 \(metres\), got nan$"):
        Protocol.from_dict({"sensor_range": float("nan")})
    with pytest.raises(ValueError, match=r"^protocol\.lidar: unknown setting \(known: cell_size, .*\), got 20$"):
        Protocol.from_dict({"lidar": 20})
    with pytest.raises(ValueError, match=r"^protocol\.max_steps: must be a whole number >= 1 \(waypoints\), got True$"):
        Protocol.from_dict({"max_steps": True})
    with pytest.raises(ValueError, match=r"^protocol: node_resolution \(0\.1 m\) must be at least one cell"):
        Protocol.from_dict({"node_resolution": 0.1})


def test_model_input_differences_name_each_changed_value():
    trained = Protocol(node_resolution=2.0, sensor_range=10.0).to_dict()
    assert model_input_differences(trained, Protocol(node_resolution=2.0, sensor_range=10.0)) == []
    assert model_input_differences(trained, Protocol()) == ["node_resolution 2 -> 4", "sensor_range 10 -> 20"]


def test_cell_size_and_episode_rules_are_not_model_inputs():
    """A node image holds one pixel per lattice node: a ROS map at 0.05 m cells feeds the same inputs."""
    assert "cell_size" not in MODEL_INPUT_FIELDS
    other = Protocol(cell_size=0.05, done_unknown_cells=10, max_steps=20)
    assert model_input_differences(Protocol().to_dict(), other) == []


def test_an_unrecorded_protocol_stands_for_the_defaults():
    """Exports from before the record (the shipped models) were trained at the defaults."""
    assert model_input_differences(None, Protocol()) == []
    assert model_input_differences({}, Protocol(region_size=8.0)) == ["region_size 20 -> 8"]


def test_fields_a_later_version_records_are_ignored():
    trained = {**Protocol(sensor_range=10.0).to_dict(), "lidar_noise": 0.1}
    assert model_input_differences(trained, Protocol()) == ["sensor_range 10 -> 20"]
