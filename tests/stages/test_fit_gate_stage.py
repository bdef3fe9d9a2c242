"""The fit_gate DVC stage on three generated 50 m mazes."""

from __future__ import annotations

import json
import shutil

import pytest
import yaml

from pipeline.models.sliver_gate import load_gate
from pipeline.world.offices import OfficeConfig, generate_office_set
from stages import fit_gate

# These tests' own settings, over which each test writes its changes: a logistic gate on mazes alone.
BASE = {
    "maps": 48,
    "holdout_maps": 12,
    "offices": 0,
    "office_holdout": 0,
    "hidden": [],
    "min_gain": 50,
    "wall_margin": 2,
    "threshold": 0.5,
    "workers": 2,
}


def _project(tmp_path, generated_maze_dir, section, offices=0):
    shutil.copytree(generated_maze_dir, tmp_path / "data/mazes/train")
    generate_office_set(OfficeConfig(side_m=40.0), offices, tmp_path / "data/offices/train", seed=[5], progress=False)
    settings = {**BASE, **section}
    for key in [key for key, value in section.items() if value is None]:
        del settings[key]  # a test of a missing key
    (tmp_path / "params.yaml").write_text(yaml.safe_dump({"protocol": {"cell_size": 0.4}, "fit_gate": settings}))


def test_stage_fits_measures_and_logs_the_gate(tmp_path, monkeypatch, generated_maze_dir, mlflow_uri):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MLFLOW_TRACKING_URI", mlflow_uri)
    _project(tmp_path, generated_maze_dir, {"maps": 3, "holdout_maps": 1, "office_holdout": 2, "workers": 1})
    metrics = fit_gate.main("params.yaml")  # no office floors: their holdout is moot, mazes alone fit a logistic gate
    assert metrics["offices_fit"] == metrics["offices_holdout"] == 0 and "auc_holdout_offices" not in metrics
    gate, protocol = load_gate(tmp_path / "models/sliver_gate/sliver_gate.json")
    assert protocol["cell_size"] == 0.4 and gate.min_gain == 50 and gate.range_cells == 50.0
    written = json.loads((tmp_path / "reports/sliver_gate.json").read_text())
    assert written == metrics and written["maps_fit"] == 2 and written["samples_fit"] > 100
    assert 0.5 < written["auc_holdout"] <= 1.0  # better than chance on a maze it was not fitted on
    import mlflow

    client = mlflow.MlflowClient(tracking_uri=mlflow_uri)
    (run,) = client.search_runs(
        [client.get_experiment_by_name("sliver_gate").experiment_id],
        order_by=["attribute.start_time DESC"],
        max_results=1,
    )
    assert [i.dataset.name for i in run.inputs.dataset_inputs] == ["data/mazes/train"]  # no floors drawn here
    assert (tmp_path / "reports/sliver_gate.png").stat().st_size > 5000
    first = (tmp_path / "models/sliver_gate/sliver_gate.json").read_bytes()
    fit_gate.main("params.yaml")
    assert (tmp_path / "models/sliver_gate/sliver_gate.json").read_bytes() == first  # a rerun writes the same bytes


@pytest.mark.parametrize(
    ("section", "message"),
    [
        ({"maps": 3, "holdout_maps": 3}, r"fit_gate: holdout_maps \(3\) must be below maps \(3\)"),
        ({"maps": 0}, r"fit_gate\.maps: must be a whole number >= 1"),
        ({"min_gain": 2.5}, r"fit_gate\.min_gain: must be a whole number >= 0 \(cells\)"),
        (
            {"mpas": 3},
            r"fit_gate\.mpas: unknown setting \(known: maps, holdout_maps, offices, office_holdout, hidden, fit_samples, min_gain, wall_margin, threshold, workers\)",
        ),
        ({"maps": 8, "holdout_maps": 4}, "3 maps, need more than fit_gate.holdout_maps = 4"),
        ({"offices": 2, "office_holdout": 2}, r"fit_gate: office_holdout \(2\) must be below offices \(2\)"),
        (
            {"maps": 3, "holdout_maps": 1, "offices": 5, "office_holdout": 2},
            "2 maps, need more than fit_gate.office_holdout = 2",
        ),
        ({"hidden": 16}, r"fit_gate\.hidden: must be a list of layer widths \(whole numbers >= 1; \[\]: logistic\)"),
        ({"threshold": None}, r"fit_gate\.threshold: missing \(the params file names every setting\)"),
    ],
)
def test_stage_refuses_bad_settings(tmp_path, monkeypatch, generated_maze_dir, section, message):
    monkeypatch.chdir(tmp_path)
    _project(tmp_path, generated_maze_dir, section, offices=2)
    with pytest.raises(ValueError, match=message):
        fit_gate.main("params.yaml")


def test_stage_fits_one_network_on_mazes_and_office_floors(tmp_path, monkeypatch, generated_maze_dir, mlflow_uri):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MLFLOW_TRACKING_URI", mlflow_uri)
    _project(
        tmp_path,
        generated_maze_dir,
        {"maps": 3, "holdout_maps": 1, "offices": 2, "office_holdout": 1, "hidden": [8], "workers": 1},
        offices=2,
    )
    metrics = fit_gate.main("params.yaml")
    gate, _ = load_gate(tmp_path / "models/sliver_gate/sliver_gate.json")
    assert [len(biases) for _, biases in gate.layers] == [8, 1]
    assert metrics["maps_fit"] == 2 and metrics["offices_fit"] == 1 and metrics["offices_holdout"] == 1
    assert metrics["samples_holdout"] > 0 and metrics["samples_holdout_offices"] > 0
    assert 0.5 < metrics["auc_holdout_offices"] <= 1.0  # better than chance on a floor it was not fitted on
    fitted_on = json.loads((tmp_path / "models/sliver_gate/sliver_gate.json").read_text())["fitted_on"]["maps"]
    assert fitted_on == ["maze_0000.png", "maze_0001.png", "office_0000.png"]
