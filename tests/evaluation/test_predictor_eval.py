from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest
import yaml

from pipeline.evaluation.predictor_eval import (
    COLUMNS,
    DETAIL_COLUMNS,
    SWEEP_COLUMNS,
    all_free_inpaint,
    evaluate_predictor,
    evaluate_with_sweep,
    load_inpaint_fn,
    oracle_inpaint_for,
    precision_by_threshold,
)
from pipeline.prediction.node_predictor import NodePredictorConfig
from pipeline.reporting.predictor_figures import prediction_figure
from pipeline.reporting.table_markdown import table1_markdown
from pipeline.workflows import table1
from pipeline.world.maps import list_maps
from pipeline.world.mazes import MazeConfig, generate_maze, write_maze_png

STEPS = (3, 6)
# The stage's settings these tests run with, each test writing its changes over them.
STAGE = {
    "steps": [15, 30, 45, 60],
    "threshold": 0.8,
    "min_component": 3,
    "keep_share": 0.5,
    "sweep_thresholds": [0.5, 0.6, 0.7, 0.8, 0.9],
    "checkpoint": None,
    "compare_checkpoint": None,
}


@pytest.fixture(scope="module")
def maze_dir(tmp_path_factory):
    directory = tmp_path_factory.mktemp("predictor_mazes")
    for i in range(2):
        image = generate_maze(MazeConfig(side_m=(50.0, 50.0)), np.random.default_rng([31, i]))
        write_maze_png(image, directory / f"maze_{i:04d}.png")
    return directory


@pytest.fixture(scope="module")
def maze_paths(maze_dir):
    return sorted(maze_dir.glob("*.png"))


def test_oracle_predictions_are_all_free(maze_paths):
    frame = evaluate_predictor(maze_paths, steps=STEPS, inpaint_for=oracle_inpaint_for)
    assert tuple(frame.columns) == DETAIL_COLUMNS
    assert frame["step"].tolist() == list(STEPS)
    assert (frame["maps"] == 2).all()
    assert (frame["predicted_nodes"] > 0).all()
    assert (frame["predictions_precision"] == 1.0).all()  # every kept prediction is a true free node
    assert (frame["precision"] <= 1.0).all() and (frame["centroids"] <= frame["predicted_nodes"]).all()
    assert (frame["prediction_ms_median"] > 0).all()
    # The base rate is what calling every asked node free scores: an oracle beats it.
    assert ((frame["base_rate"] > 0.2) & (frame["base_rate"] < frame["predictions_precision"])).all()


def test_precision_counts_the_centroid_nodes_of_v_u(maze_paths, monkeypatch):
    """Pre(k) is over all of V_u: a centroid on a wall counts against it, as in the paper."""
    import pipeline.evaluation.predictor_eval as predictor_eval

    monkeypatch.setattr(
        predictor_eval.Prediction, "centroid_cells", lambda self: np.array([[0, 0], [-5, 3]])
    )  # a border wall and a cell off the map
    frame = evaluate_predictor(maze_paths[:1], steps=STEPS, inpaint_for=oracle_inpaint_for)
    kept = frame["predicted_nodes"] - frame["centroids"]
    assert (frame["centroids"] == 2).all() and (frame["predictions_precision"] == 1.0).all()
    assert np.allclose(frame["precision"], kept / frame["predicted_nodes"])


def test_cells_free_in_truth_is_false_off_the_map(maze_paths):
    from pipeline.evaluation.predictor_eval import cells_free_in_truth
    from pipeline.world.maps import load_map

    ground_truth = load_map(maze_paths[0])
    col, row = ground_truth.start_cell
    cells = np.array([[col, row], [0, 0], [-1, row], [col, 10**6]])
    assert cells_free_in_truth(ground_truth, cells).tolist() == [True, False, False, False]


def test_an_all_free_predictor_is_not_precise(maze_paths):
    frame = evaluate_predictor(maze_paths, all_free_inpaint, steps=STEPS)
    assert tuple(frame.columns) == DETAIL_COLUMNS
    assert (frame["precision"] < 1.0).all() and (frame["precision"] > 0.0).all()
    table = table1_markdown(frame)
    assert "| 3 |" in table and "%" in table


def test_steps_no_map_reaches_have_no_precision(maze_paths):
    frame = evaluate_predictor(maze_paths[:1], all_free_inpaint, steps=(2, 10_000))
    late = frame[frame["step"] == 10_000].iloc[0]
    assert late["maps"] == 0 and late["predicted_nodes"] == 0 and np.isnan(late["precision"])


def test_exactly_one_inpainter_is_required(maze_paths):
    with pytest.raises(ValueError, match="exactly one"):
        evaluate_predictor(maze_paths, steps=STEPS)


def test_prediction_figure_has_three_panels(maze_paths, tmp_path):
    out = tmp_path / "fig3.png"
    image = prediction_figure(maze_paths[0], 6, all_free_inpaint, out_path=out)
    assert image is not None and image.ndim == 3 and image.shape[2] == 3
    assert image.shape[1] > 2.5 * image.shape[0] / 1.3  # three map panels side by side
    assert cv2.imread(str(out)).shape == image.shape
    assert prediction_figure(maze_paths[0], 10_000, all_free_inpaint) is None


def test_missing_checkpoint_is_a_clear_error(tmp_path, monkeypatch):
    with pytest.raises(FileNotFoundError, match="not found"):
        load_inpaint_fn(str(tmp_path / "nope.pt"))
    monkeypatch.chdir(tmp_path)
    import pipeline.models.defaults as planners_module

    pipeline_file = planners_module.MODEL_FILES["inpainter"][0]
    monkeypatch.setitem(planners_module.MODEL_FILES, "inpainter", (pipeline_file, (tmp_path / "no_shipped.pt",)))
    with pytest.raises(FileNotFoundError, match="train_inpainter"):
        load_inpaint_fn(None)


def test_stage_writes_reports_and_logs_a_run(maze_dir, tmp_path, monkeypatch, mlflow_uri):
    import pipeline.workflows.table1 as predictor_eval
    import stages.eval_predictor as stage

    (tmp_path / "data" / "mazes").mkdir(parents=True)
    (tmp_path / "data" / "mazes" / "test").symlink_to(maze_dir, target_is_directory=True)
    (tmp_path / "params.yaml").write_text(
        yaml.safe_dump(
            {
                "protocol": {"cell_size": 0.4},
                "eval_predictor": {**STAGE, "steps": [3, 6], "threshold": 0.5, "min_component": 3, "checkpoint": None},
            }
        )
    )
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MLFLOW_TRACKING_URI", mlflow_uri)
    monkeypatch.setattr(predictor_eval, "load_inpaint_fn", lambda checkpoint=None: all_free_inpaint)
    frame = stage.main("params.yaml")
    out = tmp_path / "reports" / "predictor"
    written = pd.read_csv(out / "precision.csv")
    assert tuple(written.columns) == COLUMNS and len(written) == 2  # the columns, exactly
    assert np.allclose(written["precision"], frame["precision"])
    detail = pd.read_csv(out / "precision_detail.csv")
    assert tuple(detail.columns) == DETAIL_COLUMNS and np.allclose(detail["precision"], written["precision"])
    assert "75.92" in (out / "table1.md").read_text()
    assert (out / "fig3.png").is_file()
    sweep = pd.read_csv(out / "precision_by_threshold.csv")  # sweep_thresholds left out: the default five tau
    assert tuple(sweep.columns) == SWEEP_COLUMNS and sorted(sweep["threshold"].unique()) == [0.5, 0.6, 0.7, 0.8, 0.9]
    at_half = sweep[sweep["threshold"] == 0.5]
    assert np.allclose(at_half["precision"], written["precision"])  # the table's own tau, the same numbers
    assert (out / "threshold_sweep.png").stat().st_size > 0 and "Precision against tau" in (
        out / "table1.md"
    ).read_text()

    import mlflow

    mlflow.set_tracking_uri(mlflow_uri)
    runs = mlflow.search_runs(experiment_names=["table1"], order_by=["attributes.start_time DESC"])
    assert len(runs) >= 1  # the session's store may hold other tests' runs: the newest is this one
    assert runs.iloc[0]["metrics.precision_step3"] == pytest.approx(float(frame["precision"].iloc[0]))
    assert runs.iloc[0]["metrics.precision_step6"] == pytest.approx(float(frame["precision"].iloc[1]))
    assert "metrics.compare_precision_step3" not in runs.columns or np.isnan(
        runs.iloc[0]["metrics.compare_precision_step3"]
    )
    assert pd.read_csv(out / "precision_compare.csv").empty  # no compare_checkpoint: a header, so DVC finds its output


def test_stage_compares_another_inpainter_on_the_same_explorations(maze_dir, tmp_path, monkeypatch, mlflow_uri):
    """compare_checkpoint: Table I again with that export; the table says which steps reach the paper's."""
    import pipeline.workflows.table1 as predictor_eval
    import stages.eval_predictor as stage

    (tmp_path / "data" / "mazes").mkdir(parents=True)
    (tmp_path / "data" / "mazes" / "test").symlink_to(maze_dir, target_is_directory=True)
    (tmp_path / "other.pt").write_bytes(b"stand-in")
    section = {**STAGE, "steps": [3, 6], "threshold": 0.5, "sweep_thresholds": [], "compare_checkpoint": "other.pt"}
    (tmp_path / "params.yaml").write_text(yaml.safe_dump({"protocol": {}, "eval_predictor": section}))
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MLFLOW_TRACKING_URI", mlflow_uri)
    networks = {None: graded_inpaint, "other.pt": all_free_inpaint}
    monkeypatch.setattr(predictor_eval, "load_inpaint_fn", lambda checkpoint=None: networks[checkpoint])
    monkeypatch.setattr(
        predictor_eval,
        "run",
        lambda *a, **k: (
            Path(a[1]).mkdir(parents=True, exist_ok=True),
            (Path(a[1]) / "table1.md").write_text("# Table I\n"),
            pd.DataFrame(columns=list(COLUMNS)),
        )[-1],
    )
    stage.main("params.yaml")
    out = tmp_path / "reports" / "predictor"
    compared = pd.read_csv(out / "precision_compare.csv")
    expected = evaluate_predictor(
        list_maps(maze_dir),
        all_free_inpaint,
        [3, 6],
        NodePredictorConfig(threshold=0.5),
        table1.table1_graph_config(0.5),
    )
    assert tuple(compared.columns) == COLUMNS
    assert np.allclose(compared["precision"], expected["precision"])
    assert list(compared["predicted_nodes"]) == list(expected["predicted_nodes"])
    table = (out / "table1.md").read_text()
    assert table.startswith("# Table I") and "Another inpainter: other.pt" in table
    (tmp_path / "params.yaml").write_text(
        yaml.safe_dump({"eval_predictor": {**section, "compare_checkpoint": "gone.pt"}})
    )
    with pytest.raises(FileNotFoundError, match="gone.pt"):
        stage.main("params.yaml")


def test_table1_for_folder_writes_precision_csv(maze_dir, tmp_path, monkeypatch):
    import pipeline.workflows.table1 as predictor_eval
    import stages.eval_predictor as stage

    seen = []
    monkeypatch.setattr(predictor_eval, "PAPER_STEPS", STEPS)
    monkeypatch.setattr(
        predictor_eval, "load_inpaint_fn", lambda checkpoint=None: seen.append(checkpoint) or all_free_inpaint
    )
    table1.table1_for_folder(maze_dir, tmp_path / "out", "some.pt")
    assert seen == ["some.pt"]
    written = pd.read_csv(tmp_path / "out" / "precision.csv")
    assert tuple(written.columns) == COLUMNS
    assert not (tmp_path / "out" / "precision_by_threshold.csv").exists()  # the sweep only on request
    assert "tau = 0.8." in (tmp_path / "out" / "table1.md").read_text()  # the planners' tau unless told
    table1.table1_for_folder(maze_dir, tmp_path / "swept", None, sweep=True)
    assert len(pd.read_csv(tmp_path / "swept" / "precision_by_threshold.csv")) == 5 * len(STEPS)
    with pytest.raises(ValueError, match=r"must lie in \[0, 1\], got 1.5"):
        table1.table1_for_folder(maze_dir, tmp_path / "bad_tau", None, threshold=1.5)
    with pytest.raises(ValueError, match=r"eval_predictor\.stepz: unknown setting \(known: steps, "):
        (tmp_path / "bad.yaml").write_text(yaml.safe_dump({"eval_predictor": {**STAGE, "stepz": [1]}}))
        stage.read_params(tmp_path / "bad.yaml")


def test_table1_for_folder_threshold_is_the_sweeps_row_at_that_tau(maze_dir, tmp_path, monkeypatch):
    """`guide eval-predictor --threshold 0.7` gives what the sweep reports at tau 0.7, and its table says so."""
    import pipeline.workflows.table1 as predictor_eval

    monkeypatch.setattr(predictor_eval, "PAPER_STEPS", STEPS)
    monkeypatch.setattr(predictor_eval, "load_inpaint_fn", lambda checkpoint=None: graded_inpaint)
    at_07 = table1.table1_for_folder(maze_dir, tmp_path / "t07", None, threshold=0.7)
    written_07 = pd.read_csv(tmp_path / "t07" / "precision.csv")
    table1.table1_for_folder(maze_dir, tmp_path / "sweep", None, sweep=True)
    sweep = pd.read_csv(tmp_path / "sweep" / "precision_by_threshold.csv")
    row_07 = sweep[np.isclose(sweep["threshold"], 0.7)].reset_index(drop=True)
    row_05 = sweep[np.isclose(sweep["threshold"], 0.5)].reset_index(drop=True)
    at_default = pd.read_csv(tmp_path / "sweep" / "precision.csv")  # the planners' tau, 0.8
    assert np.allclose(written_07["precision"], row_07["precision"], equal_nan=True)
    assert list(written_07["predicted_nodes"]) == list(row_07["predicted_nodes"])
    assert (at_07["predicted_nodes"] < row_05["predicted_nodes"]).all()  # a higher tau keeps fewer nodes
    assert (at_default["predicted_nodes"] < at_07["predicted_nodes"]).all()
    assert "tau = 0.7." in (tmp_path / "t07" / "table1.md").read_text()


def graded_inpaint(image):
    """A fixed spread of probabilities 0.05-0.95 over the image, so each tau keeps a different set."""
    rows, cols = np.indices(image.shape)
    return ((rows * 7 + cols * 13) % 10) / 10.0 + 0.05


def test_precision_by_threshold_equals_one_evaluation_per_tau_with_one_network_call(maze_paths):
    calls = []

    def counting(image):
        calls.append(1)
        return graded_inpaint(image)

    sweep = precision_by_threshold(maze_paths, counting, [0.3, 0.7], steps=STEPS)
    assert tuple(sweep.columns) == SWEEP_COLUMNS and len(sweep) == 2 * len(STEPS)
    checkpoints = 2 * len(STEPS)  # both mazes reach both steps
    assert len(calls) == checkpoints + 2 * 2  # one call per checkpoint for both tau, plus 2 warm-ups per map
    for tau in (0.3, 0.7):
        alone = evaluate_predictor(maze_paths, graded_inpaint, STEPS, NodePredictorConfig(threshold=tau))
        mine = sweep[sweep["threshold"] == tau].reset_index(drop=True)
        assert mine["predicted_nodes"].tolist() == alone["predicted_nodes"].tolist()
        assert np.allclose(mine["precision"], alone["precision"])
        assert np.allclose(mine["nodes_per_map"], alone["predicted_nodes"] / alone["maps"])
    low, high = (sweep[sweep["threshold"] == t]["predicted_nodes"].sum() for t in (0.3, 0.7))
    assert high < low  # a higher tau keeps fewer nodes


def test_precision_by_threshold_refuses_bad_thresholds(maze_paths):
    with pytest.raises(ValueError, match="at least one threshold"):
        precision_by_threshold(maze_paths, graded_inpaint, [], steps=STEPS)
    with pytest.raises(ValueError, match=r"thresholds must lie in \[0, 1\], got 1.5"):
        precision_by_threshold(maze_paths, graded_inpaint, [0.5, 1.5], steps=STEPS)


def test_stage_refuses_a_bad_sweep(tmp_path):
    import stages.eval_predictor as stage

    (tmp_path / "p.yaml").write_text(yaml.safe_dump({"eval_predictor": {**STAGE, "sweep_thresholds": [0.5, 2]}}))
    with pytest.raises(ValueError, match=r"eval_predictor\.sweep_thresholds\[1\]: must be a number in \[0, 1\], got 2"):
        stage.read_params(tmp_path / "p.yaml")
    (tmp_path / "q.yaml").write_text(yaml.safe_dump({"eval_predictor": {**STAGE, "sweep_thresholds": None}}))
    assert stage.read_params(tmp_path / "q.yaml")[0].sweep_thresholds is None  # no sweep


def test_evaluate_with_sweep_is_table1_and_the_sweep_from_one_exploration(maze_paths):
    calls = []

    def counting(image):
        calls.append(1)
        return graded_inpaint(image)

    frame, sweep = evaluate_with_sweep(maze_paths, counting, [0.3, 0.7], STEPS, NodePredictorConfig(threshold=0.5))
    assert len(calls) == 2 * len(STEPS) + 2 * 2  # one network call per checkpoint, plus the warm-ups
    alone = evaluate_predictor(maze_paths, graded_inpaint, STEPS, NodePredictorConfig(threshold=0.5))
    assert frame["predicted_nodes"].tolist() == alone["predicted_nodes"].tolist()
    assert np.allclose(frame["precision"], alone["precision"]) and (frame["prediction_ms_median"] > 0).all()
    separate = precision_by_threshold(maze_paths, graded_inpaint, [0.3, 0.7], steps=STEPS)
    pd.testing.assert_frame_equal(sweep, separate)
