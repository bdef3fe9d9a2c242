"""The train_block_model DVC stage on three generated 50 m mazes."""

from __future__ import annotations

import json

import pytest
import torch
import yaml

from pipeline.models.modeling_block_model import load_block_model
from stages import train_block_model

SMALL = {
    "mazes": 3,
    "holdout_mazes": 1,
    "side_m": 50.0,
    "maze_seed": 555,
    "snapshot_every": 2,
    "epochs": 2,
    "batch_size": 32,
    "lr": 3e-3,
    "reveal_share": 0.7,
    "workers": 1,
    "seed": 0,
    "model": {"width": 8, "dilations": [1, 2], "groups": 4},
}


def _project(tmp_path, section):
    settings = {**SMALL, **section}
    for key in [key for key, value in section.items() if value is None]:
        del settings[key]  # a test of a missing key
    (tmp_path / "params.yaml").write_text(
        yaml.safe_dump({"protocol": {"cell_size": 0.4}, "train_block_model": settings})
    )


def test_stage_trains_measures_and_logs_the_block_model(tmp_path, monkeypatch, mlflow_uri):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MLFLOW_TRACKING_URI", mlflow_uri)
    _project(tmp_path, SMALL)
    metrics = train_block_model.main("params.yaml")
    model = load_block_model(tmp_path / "models/block_model/block_model.pt")
    assert model.config.width == 8 and model.config.dilations == (1, 2)
    written = json.loads((tmp_path / "reports/block_model.json").read_text())
    assert written == metrics and written["mazes_fit"] == 2 and written["snapshots_fit"] >= 5
    assert [row["epoch"] for row in written["history"]] == [1, 2]
    assert 0.0 <= written["held_out_error"] <= 1.0 and 0.0 < written["held_out_error_all_wall"] < 1.0
    assert (tmp_path / "reports/block_model.png").stat().st_size > 5000
    trained_on = torch.load(tmp_path / "models/block_model/block_model.pt", weights_only=True)["trained_on"]
    assert trained_on["mazes"] == {"mazes": 3, "side_m": 50.0, "maze_seed": 555}
    assert not (tmp_path / "data").exists()  # its mazes were drawn in a temporary folder
    import mlflow

    client = mlflow.MlflowClient(tracking_uri=mlflow_uri)
    (run,) = client.search_runs(
        [client.get_experiment_by_name("block_model").experiment_id],
        order_by=["attribute.start_time DESC"],
        max_results=1,
    )
    (drawn,) = run.inputs.dataset_inputs  # recorded by the settings they were drawn from
    assert drawn.dataset.name.startswith("block model mazes (3 of 50 m, seed 555)") and drawn.dataset.digest


@pytest.mark.parametrize(
    ("section", "message"),
    [
        ({"mazes": 3, "holdout_mazes": 3}, r"train_block_model: holdout_mazes \(3\) must be below mazes \(3\)"),
        ({"epochs": 0}, r"train_block_model\.epochs: must be a whole number >= 1"),
        ({"reveal_share": 1.5}, r"train_block_model\.reveal_share: must be a number in \[0, 1\]"),
        (
            {"epoch": 3},
            r"train_block_model\.epoch: unknown setting \(known: mazes, holdout_mazes, side_m, maze_seed, snapshot_every, epochs, batch_size, lr, reveal_share, model, workers, seed\)",
        ),
        ({"side_m": 52.0}, r"train_block_model.side_m: MazeConfig.side_m \(52.0, 52.0\) holds no whole number"),
        ({"side_m": "big"}, r"train_block_model\.side_m: must be a finite number > 0 \(metres\)"),
        ({"model": {"width": 10, "groups": 4}}, r"train_block_model\.model: groups \(4\) must divide width \(10\)"),
        ({"lr": None}, r"train_block_model\.lr: missing \(the params file names every setting\)"),
    ],
)
def test_stage_refuses_bad_settings(tmp_path, monkeypatch, section, message):
    monkeypatch.chdir(tmp_path)
    _project(tmp_path, section)
    with pytest.raises(ValueError, match=message):
        train_block_model.main("params.yaml")
