import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from pipeline.cli import app
from pipeline.world.maps import GroundTruthMap, load_ros_map
from pipeline.world.resample import remove_specks, resample_factor, resample_free, resample_map, write_ros_map
from tests.conftest import write_ros_map as write_fine_ros_map

runner = CliRunner()


def office_at_5cm(seed: int = 0) -> np.ndarray:
    """A 20 m x 16 m room at 0.05 m with a wall (one door) and chair-leg specks: free[row, col]."""
    free = np.zeros((320, 400), dtype=bool)
    free[8:312, 8:392] = True
    free[8:312, 197:203] = False  # a 0.3 m wall across the room ...
    free[140:180, 197:203] = True  # ... with a 2 m door
    rng = np.random.default_rng(seed)
    for row, col in rng.integers((20, 20), (300, 380), size=(30, 2)):
        free[row : row + 2, col : col + 2] = False  # 0.1 m specks
    return free


def test_the_factor_is_a_whole_number_of_cells():
    assert resample_factor(0.05, 0.4) == 8 and resample_factor(0.05, 0.3) == 6 and resample_factor(0.4, 0.4) == 1
    with pytest.raises(
        ValueError, match=r"not a whole number of the map's 0.05 m cells; use a multiple, e.g. 0.3 or 0.35 m"
    ):
        resample_factor(0.05, 0.33)
    with pytest.raises(ValueError, match="positive"):
        resample_factor(0.05, 0.0)


def test_any_obstacle_cell_keeps_a_thin_wall_closed_where_a_count_opens_it():
    """One-cell lines at random angles across a 0.05 m grid, resampled to 0.4 m: with the default
    (any obstacle cell makes a wall) both sides stay apart under the 4-connected rays and moves."""
    rng = np.random.default_rng(1)
    broken = {1: 0, 8: 0}
    for _ in range(20):
        angle, centre = rng.uniform(0, np.pi), rng.uniform(60, 140, 2)
        ends = [
            tuple(int(v) for v in centre + sign * 300 * np.array([np.cos(angle), np.sin(angle)])) for sign in (-1, 1)
        ]
        line = np.zeros((200, 200), np.uint8)
        cv2.line(line, ends[0], ends[1], 1, 1, lineType=cv2.LINE_8)
        free = line == 0
        start = tuple(int(v) for v in np.argwhere(free)[0][::-1])
        default, _ = resample_map(GroundTruthMap(free=free, start_cell=start, cell_size=0.05), 0.4)
        for wall_cells, coarse in ((1, default.free), (8, resample_free(free, 8, 8))):
            broken[wall_cells] += cv2.connectedComponents(coarse.astype(np.uint8), connectivity=4)[0] - 1 < 2
    assert broken[1] == 0
    assert broken[8] > 10  # why the default counts any obstacle cell


def test_specks_are_erased_before_the_blocks_are_pooled():
    free = office_at_5cm()
    cleaned = remove_specks(free, 40)  # 0.1 m^2 at 0.05 m
    assert cleaned[20:300, 20:190].all()  # the specks are gone ...
    assert not cleaned[200:300, 197:203].any() and not cleaned[:8].any()  # ... the walls stay
    ground_truth = GroundTruthMap(free=free, start_cell=(60, 60), cell_size=0.05, name="office")
    coarse, moved = resample_map(ground_truth, 0.4)
    assert coarse.free.shape == (40, 50) and coarse.cell_size == 0.4 and coarse.start_cell == (7, 7) and moved == 0.0
    assert coarse.free[2:38, 2:24].all()  # the left half of the room: no speck became a 0.4 m block
    assert not coarse.free[:, 24:26][25:36].any()  # the wall below the door stays closed
    assert coarse.free[18:22, 22:28].all()  # and the 2 m door stays open
    with_specks, _ = resample_map(ground_truth, 0.4, speck_area=0.0)
    assert with_specks.free_cell_count < coarse.free_cell_count - 20


def test_the_start_moves_to_the_nearest_free_cell_when_its_own_becomes_a_wall():
    free = office_at_5cm()
    ground_truth = GroundTruthMap(free=free, start_cell=(195, 100), cell_size=0.05, name="office")  # beside the wall
    coarse, moved = resample_map(ground_truth, 0.4)
    col, row = coarse.start_cell
    assert coarse.free[row, col] and (col, row) == (23, 12) and moved == pytest.approx(0.4)


def test_the_written_map_reads_back_the_same(tmp_path):
    free = office_at_5cm()
    ground_truth = GroundTruthMap(free=free, start_cell=(60, 60), cell_size=0.05, name="office")
    coarse, _ = resample_map(ground_truth, 0.4)
    image = write_ros_map(coarse, tmp_path / "coarse.yaml", origin=(-3.0, 2.0))
    assert image == tmp_path / "coarse.pgm"
    loaded = load_ros_map(tmp_path / "coarse.yaml")
    assert np.array_equal(loaded.free, coarse.free) and loaded.start_cell == coarse.start_cell
    assert loaded.cell_size == 0.4


def test_resample_map_command_writes_a_map_the_planners_explore(tmp_path):
    fine = write_fine_ros_map(tmp_path, office_at_5cm(), 0.05, (3.0, 3.0))
    result = runner.invoke(
        app,
        [
            "explore",
            "--map",
            str(fine),
            "--planner",
            "nearest_frontier",
            "--no-progress",
            "--max-steps",
            "1",
            "--out",
            str(tmp_path / "fine"),
        ],
    )
    assert "warning: office is drawn at 0.05 m per cell: the lidar's rays pass 3.5 cells apart at 20 m" in result.output
    out = tmp_path / "coarse" / "office.yaml"
    result = runner.invoke(app, ["resample-map", "--map", str(fine), "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "400x320 cells of 0.05 m -> 50x40 cells of 0.4 m" in result.output
    assert load_ros_map(out).cell_size == 0.4
    result = runner.invoke(
        app,
        ["explore", "--map", str(out), "--planner", "greedy_utility", "--no-progress", "--out", str(tmp_path / "run")],
    )
    assert result.exit_code == 0 and "complete" in result.output and "warning" not in result.output
    result = runner.invoke(
        app, ["resample-map", "--map", str(fine), "--out", str(tmp_path / "c.yaml"), "--to-cell-size", "0.33"]
    )
    assert result.exit_code == 2 and "not a whole number of the map's 0.05 m cells" in result.output
    result = runner.invoke(app, ["resample-map", "--map", str(fine), "--out", str(tmp_path / "c.png")])
    assert result.exit_code == 2 and "name the ROS map YAML to write" in result.output
    before = (tmp_path / "office.pgm").read_bytes()
    result = runner.invoke(app, ["resample-map", "--map", str(fine), "--out", str(tmp_path / "office.yml")])
    assert result.exit_code == 2 and "would overwrite the map being read" in result.output
    assert (tmp_path / "office.pgm").read_bytes() == before
