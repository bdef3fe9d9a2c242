"""Shared fixtures: small maps the tests make themselves (nothing reads ../shared)."""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np
import pytest

os.environ.setdefault("MLFLOW_DISABLE_TELEMETRY", "true")
os.environ.setdefault("DVC_NO_ANALYTICS", "1")

from tiny_project import TinyRun, tiny_reference_run  # noqa: E402

from pipeline.world.maps import GroundTruthMap, load_maze_png  # noqa: E402
from pipeline.world.mazes import MazeConfig, generate_maze, write_maze_png  # noqa: E402

WALL, FREE, START = 127, 195, 208

# guide's single-node targets (its config's own defaults), set where a test at the maze protocol is of
# them: that protocol gives guide, guide_noregion and dare guide_tsp's clusters instead.
SINGLE_NODES = {"spread": 0.0, "min_weight": 0.0, "beta": 0.0, "exact_max": 2, "max_moves": 0}


def pytest_collection_modifyitems(config, items) -> None:
    """The tests of one `xdist_group` (the shared tiny `dvc repro` and the Ray clusters) first: they
    run one after another on one worker, the longest chain of the suite, so it starts at once
    while the other workers share the rest, the other slow tests first."""
    items.sort(
        key=lambda item: (item.get_closest_marker("xdist_group") is None, item.get_closest_marker("slow") is None)
    )


def maze_from_blocks(blocks: list[str], block_px: int = 25) -> np.ndarray:
    """A maze PNG image from a picture of blocks: '#' wall, '.' free, 'S' the start block."""
    rows, cols = len(blocks), len(blocks[0])
    image = np.full((rows * block_px, cols * block_px), WALL, dtype=np.uint8)
    values = {"#": WALL, ".": FREE, "S": START}
    for r, line in enumerate(blocks):
        for c, char in enumerate(line):
            image[r * block_px : (r + 1) * block_px, c * block_px : (c + 1) * block_px] = values[char]
    return image


SMALL_MAZE = [
    "##########",
    "#S...#...#",
    "#.##.#.#.#",
    "#.#..#.#.#",
    "#.#.##.#.#",
    "#...#..#.#",
    "###.#.##.#",
    "#.......##",
    "#..#.....#",
    "##########",
]


@pytest.fixture(scope="session")
def small_maze_path(tmp_path_factory) -> Path:
    """A hand-drawn 50 m maze PNG in the benchmark format."""
    path = tmp_path_factory.mktemp("maps") / "small.png"
    write_maze_png(maze_from_blocks(SMALL_MAZE), path)
    return path


@pytest.fixture(scope="session")
def small_maze(small_maze_path) -> GroundTruthMap:
    return load_maze_png(small_maze_path)


@pytest.fixture(scope="session")
def tiny_reference(tmp_path_factory) -> TinyRun:
    """One uninterrupted `dvc repro` of a tiny copy, shared by the end-to-end, Ray and chaos tests
    (read only: each test that changes a project makes its own)."""
    return tiny_reference_run(tmp_path_factory.mktemp("tiny") / "project")


@pytest.fixture(scope="session")
def generated_maze_dir(tmp_path_factory) -> Path:
    """Three generated 50 m mazes, as the maze stage writes them."""
    directory = tmp_path_factory.mktemp("mazes")
    config = MazeConfig(side_m=(50.0, 50.0))
    for i in range(3):
        write_maze_png(generate_maze(config, np.random.default_rng([7, i])), directory / f"maze_{i:04d}.png")
    return directory


def write_ros_map(
    directory: Path, free: np.ndarray, resolution: float, start_xy: tuple[float, float], name: str = "office"
) -> Path:
    """A ROS map_server map (PGM + YAML); `free[row, col]` with row 0 at y = origin (bottom)."""
    image = np.where(free, 254, 0).astype(np.uint8)[::-1]  # image row 0 is the top
    cv2.imwrite(str(directory / f"{name}.pgm"), image)
    yaml_path = directory / f"{name}.yaml"
    yaml_path.write_text(
        f"image: {name}.pgm\nresolution: {resolution}\norigin: [0.0, 0.0, 0.0]\n"
        f"negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\nstart: [{start_xy[0]}, {start_xy[1]}]\n"
    )
    return yaml_path


@pytest.fixture(autouse=True)
def no_pipeline_models(monkeypatch, tmp_path):
    """Tests never pick up models a `dvc repro` left in the working tree (models/...): a learned
    planner built without a checkpoint gets the shipped default, as in a fresh clone."""
    from pipeline.models import defaults

    absent = tmp_path / "no-pipeline-models"
    for kind, (pipeline, shipped) in list(defaults.MODEL_FILES.items()):  # the catalogue every default goes through
        monkeypatch.setitem(defaults.MODEL_FILES, kind, (absent / pipeline.name, shipped))


TEST_EXPERIMENTS = (
    "benchmark",
    "table1",
    "cli-test",
    "test_planner",
    "sliver_gate",
    "block_model",
    "drl",
)  # "inpainter-test" sets its own location


@pytest.fixture(scope="session")
def mlflow_uri(tmp_path_factory) -> str:
    """One sqlite MLflow store for the whole session (creating one costs seconds).

    The experiments the tests log to are created here with their artifacts in the same
    temporary folder: on a sqlite store MLflow would otherwise put them in ./mlruns.
    """
    import mlflow

    from pipeline.reporting.mlflow_tables import TABLE_EXPERIMENTS

    folder = tmp_path_factory.mktemp("mlflow")
    uri = f"sqlite:///{folder / 'mlflow.db'}"
    client = mlflow.MlflowClient(tracking_uri=uri)
    for name in sorted(set(TEST_EXPERIMENTS) | set(TABLE_EXPERIMENTS.values())):
        client.create_experiment(name, artifact_location=(folder / "artifacts" / name).as_uri())
    return uri


@pytest.fixture(scope="session")
def expert_shard_dir(generated_maze_dir, tmp_path_factory) -> Path:
    """Two expert episodes on generated 50 m mazes, stored as the collect_expert stage stores them."""
    from pipeline.data.collect import ExpertConfig, collect_expert_shard
    from pipeline.data.shards import run_shards
    from pipeline.world.maps import list_maps

    directory = tmp_path_factory.mktemp("expert")
    config = ExpertConfig(
        maps=tuple(str(p) for p in list_maps(generated_maze_dir)),
        episodes_per_shard=1,
        planner="expert",
        horizon=8,
        seed=3,
    )
    run_shards(collect_expert_shard, 2, directory, {"config": config}, progress=False)
    return directory


@pytest.fixture
def one_torch_thread():
    """Small networks run fastest on one torch thread (many threads stall on a busy 2-core machine)."""
    import torch

    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(previous)


def two_rooms(door_row: int = 28) -> GroundTruthMap:
    """12 x 24 m at 0.2 m: a wall on a lattice column (27) with a 2-cell door (0.4 m) that no straight
    edge of the 1 m lattice crosses (rows 28-29, between the node rows 27 and 32)."""
    free = np.ones((60, 120), bool)
    free[0, :] = free[-1, :] = free[:, 0] = free[:, -1] = False
    free[:, 27] = False
    free[door_row : door_row + 2, 27] = True
    return GroundTruthMap(free=free, start_cell=(12, 32), cell_size=0.2, name="two_rooms")
