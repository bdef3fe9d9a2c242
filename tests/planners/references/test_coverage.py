"""Ground-truth coverage library (pipeline/coverage.py): graph, scans, covers, TSP, tours."""

from __future__ import annotations

import itertools
import threading

import numpy as np
import pytest

from pipeline.lattice import tsp
from pipeline.lattice.graph import WINDOW_RADIUS
from pipeline.planners.references import coverage as cov
from pipeline.planners.references import coverage_model as cm
from pipeline.world.geometry import segment_is_known_free
from pipeline.world.maps import load_maze_png
from pipeline.world.mazes import MazeConfig, generate_maze, write_maze_png
from pipeline.world.protocol import Protocol
from pipeline.world.sensor import scan
from pipeline.world.simulator import replay

PROTOCOL = Protocol()
FAST = {"restarts": 4, "lns_iterations": 5}  # the search defaults are for benchmarks, not needed here


@pytest.fixture(scope="module")
def generated_maze(tmp_path_factory):
    """A generated 50 m maze."""
    path = tmp_path_factory.mktemp("coverage") / "maze.png"
    write_maze_png(generate_maze(MazeConfig(side_m=(50.0, 50.0)), np.random.default_rng([3, 6])), path)
    return load_maze_png(path)


@pytest.fixture(scope="module", params=["small", "generated"])
def maze(request, small_maze, generated_maze):
    return small_maze if request.param == "small" else generated_maze


def lattice_index(point: tuple[float, float]) -> tuple[int, int]:
    d = PROTOCOL.node_resolution
    i, j = round(point[0] / d), round(point[1] / d)
    assert abs(i * d - point[0]) < 1e-9 and abs(j * d - point[1]) < 1e-9, f"{point} is not a lattice node"
    return i, j


def point_cell(ground_truth, point: tuple[float, float]) -> tuple[int, int]:
    col = ground_truth.start_cell[0] + int(round(point[0] / PROTOCOL.cell_size))
    row = ground_truth.start_cell[1] + int(round(point[1] / PROTOCOL.cell_size))
    return col, row


def unseen_after(ground_truth, points) -> int:
    """Ground-truth free cells not revealed by scanning at every point (world metres)."""
    seen = np.zeros(ground_truth.free.size, dtype=bool)
    for point in points:
        seen[scan(ground_truth.free, point_cell(ground_truth, point), PROTOCOL.sensor_range_cells).free] = True
    return ground_truth.free_cell_count - int(seen.sum())


# --------------------------------------------------------------------------- the model
def test_ground_truth_graph_edges_are_exactly_the_free_segments(maze):
    graph = cm.ground_truth_graph(maze, PROTOCOL)
    free_nodes = maze.free.reshape(-1)[graph.node_flat]
    for (a, b), valid in zip(graph.edge_nodes, graph.edge_valid):
        expected = bool(free_nodes[a] and free_nodes[b]) and segment_is_known_free(
            maze.free, tuple(graph.node_cells[a]), tuple(graph.node_cells[b])
        )
        assert valid == expected


def test_node_scans_are_the_protocol_sensor(maze):
    model = cm.coverage_model(maze, PROTOCOL)
    assert model.nodes[model.start] == model.start_node
    assert tuple(model.node_cells[model.start]) == tuple(maze.start_cell)
    for k in range(0, model.node_count, max(1, model.node_count // 7)):
        expected = scan(maze.free, tuple(int(c) for c in model.node_cells[k]), PROTOCOL.sensor_range_cells).free
        np.testing.assert_array_equal(np.sort(model.cells[model.row(k)]), expected)
    # every coverable cell is ground-truth free
    assert maze.free.reshape(-1)[model.cells].all()


def test_all_pairs_paths_follow_ground_truth_edges(maze):
    model = cm.coverage_model(maze, PROTOCOL)
    rng = np.random.default_rng(0)
    for a, b in rng.integers(0, model.node_count, size=(20, 2)):
        path = model.path(int(a), int(b))
        assert path[0] == a and path[-1] == b
        assert abs(model.path_length(path) - model.dist[a, b]) < 1e-3
        for u, v in zip(path[:-1], path[1:]):
            assert segment_is_known_free(maze.free, tuple(model.node_cells[u]), tuple(model.node_cells[v]))


def test_model_is_cached_per_map_and_protocol(small_maze):
    assert cm.coverage_model(small_maze, PROTOCOL) is cm.coverage_model(small_maze, PROTOCOL)
    other = Protocol(done_unknown_cells=10)
    assert cm.coverage_model(small_maze, other) is not cm.coverage_model(small_maze, PROTOCOL)


# --------------------------------------------------------------------------- covers
def test_greedy_cover_covers_as_needed_not_more(maze):
    model = cm.coverage_model(maze, PROTOCOL)
    objective = cm.CoverageObjective(model, cov.uncovered_after_scan(model, model.start))
    for seed in range(3):
        chosen = cov.greedy_cover(objective, model.start, np.random.default_rng(seed), tolerance=0.2 * seed)
        points = [(0.0, 0.0)] + [tuple(model.world[v]) for v in chosen]
        assert unseen_after(maze, points) <= PROTOCOL.done_unknown_cells
        if chosen:  # without its last viewpoint the cover was not yet enough
            assert unseen_after(maze, points[:-1]) > PROTOCOL.done_unknown_cells


def test_choose_viewpoints_with_the_path_scans_complete(maze):
    model = cm.coverage_model(maze, PROTOCOL)
    viewpoints = cov.choose_viewpoints(model, seed=0, **FAST)
    order = [model.start] + [int(model.local[v]) for v in viewpoints]
    path = model.expand(order)
    assert unseen_after(maze, [tuple(model.world[v]) for v in path]) <= PROTOCOL.done_unknown_cells


def test_objective_simulation_matches_the_sensor(maze):
    model = cm.coverage_model(maze, PROTOCOL)
    objective = cm.CoverageObjective(model, cov.uncovered_after_scan(model, model.start))
    rng = np.random.default_rng(1)
    path = model.expand([model.start] + [int(v) for v in rng.integers(0, model.node_count, size=3)])
    needed, length, remaining = objective.simulate(path)
    points = [tuple(model.world[v]) for v in path[:needed]]
    assert unseen_after(maze, points) == remaining + (maze.free_cell_count - len(model.cells))
    assert length == pytest.approx(model.path_length(path[:needed]))


def test_pack_bits_puts_bit_j_in_word_j_over_64():
    rows = np.zeros((2, 130), dtype=bool)
    rows[0, [0, 63, 64, 129]] = True
    bits = cm.pack_bits(rows)
    assert bits.shape == (2, 3) and bits.dtype == np.uint64
    assert bits[0].tolist() == [1 | (1 << 63), 1, 2] and not bits[1].any()


def test_objective_counts_only_uncovered_cells_and_survives_an_empty_set(maze):
    model = cm.coverage_model(maze, PROTOCOL)
    uncovered = cov.uncovered_after_scan(model, model.start)
    objective = cm.CoverageObjective(model, uncovered)
    # A node's gain is exactly its scan's uncovered cells (bits of covered cells are masked out).
    expected = [int(uncovered[model.row(k)].sum()) for k in range(model.node_count)]
    assert objective.gain.tolist() == expected
    empty = cm.CoverageObjective(model, np.zeros_like(uncovered))
    assert empty.total == 0 and not empty.gain.any()
    assert empty.simulate([model.start])[2] == 0


# --------------------------------------------------------------------------- TSP
def brute_force_open(dist: np.ndarray) -> float:
    n = len(dist)
    return min(tsp.path_length(dist, [0, *p]) for p in itertools.permutations(range(1, n)))


@pytest.mark.parametrize("n", [2, 3, 5, 7])
def test_open_tsp_exact_for_small_instances(n):
    rng = np.random.default_rng(n)
    points = rng.random((n, 2)) * 50
    dist = np.hypot(*(points[:, None] - points[None]).transpose(2, 0, 1))
    order = tsp.open_tsp_order(dist)
    assert order[0] == 0 and sorted(order) == list(range(n))
    assert tsp.path_length(dist, order) == pytest.approx(brute_force_open(dist))


def test_open_tsp_heuristic_on_graph_distances(small_maze):
    """Lin-Kernighan + 2-opt/or-opt (forced): a permutation from 0, near the exact optimum."""
    model = cm.coverage_model(small_maze, PROTOCOL)
    rng = np.random.default_rng(0)
    for _ in range(5):
        nodes = [model.start] + [
            int(v) for v in rng.choice(model.node_count, size=9, replace=False) if v != model.start
        ]
        dist = model.dist[np.ix_(nodes, nodes)]
        heuristic = tsp.open_tsp_order(dist, exact_max_nodes=0)
        assert heuristic[0] == 0 and sorted(heuristic) == list(range(len(nodes)))
        exact = tsp.open_tsp_order(dist)
        assert tsp.path_length(dist, heuristic) <= 1.05 * tsp.path_length(dist, exact) + 1e-6


def test_open_tsp_lin_kernighan_terminates_where_float_lengths_loop(small_maze):
    """python-tsp's Lin-Kernighan never stopped on this instance with float lengths."""
    model = cm.coverage_model(small_maze, PROTOCOL)
    nodes = [1, 28, 19, 55, 33, 0, 32, 62, 49, 26, 24, 30, 45, 14, 18, 53, 69, 5, 63, 51]
    nodes = [v for v in nodes if v < model.node_count]
    dist = model.dist[np.ix_(nodes, nodes)]
    result: list[np.ndarray] = []
    worker = threading.Thread(target=lambda: result.append(tsp.open_tsp_order(dist, exact_max_nodes=0)), daemon=True)
    worker.start()
    worker.join(timeout=20)
    assert not worker.is_alive(), "open_tsp_order did not terminate"
    order = result[0]
    assert order[0] == 0 and sorted(order) == list(range(len(nodes)))
    assert tsp.path_length(dist, order) <= tsp.path_length(dist, tsp._nearest_neighbour(dist)) + 1e-6


# --------------------------------------------------------------------------- tours
def test_tour_is_a_path_on_ground_truth_edges(maze):
    tour = cov.coverage_tour(maze, PROTOCOL, seed=0, **FAST)
    assert tour[0] == (0.0, 0.0)
    for a, b in zip(tour[:-1], tour[1:]):
        (ia, ja), (ib, jb) = lattice_index(a), lattice_index(b)
        assert (ia, ja) != (ib, jb)
        assert abs(ia - ib) <= WINDOW_RADIUS and abs(ja - jb) <= WINDOW_RADIUS
        assert segment_is_known_free(maze.free, point_cell(maze, a), point_cell(maze, b))


def test_tour_replayed_under_the_oracle_rule_completes_at_its_end(maze):
    model, plan = cov.coverage_plan(maze, PROTOCOL, seed=0, **FAST)
    tour = cov.coverage_tour(maze, PROTOCOL, seed=0, **FAST)
    result = replay(maze, tour, PROTOCOL, oracle=True)
    assert result.complete and result.motion_violations == 0
    assert result.complete_after_waypoint == len(tour)  # cover as needed, not more
    assert result.distance_m == pytest.approx(plan.length)
    assert result.distance_m == pytest.approx(cov.replay_oracle(maze, tour, PROTOCOL).distance_m)


def test_tour_is_deterministic_with_the_seed(small_maze):
    assert cov.coverage_tour(small_maze, PROTOCOL, seed=3) == cov.coverage_tour(small_maze, PROTOCOL, seed=3)


def test_stricter_done_rule_needs_a_longer_tour(small_maze):
    lengths = []
    for done in (250, 0):
        protocol = Protocol(done_unknown_cells=done)
        tour = cov.coverage_tour(small_maze, protocol, **FAST)
        result = replay(small_maze, tour, protocol, oracle=True)
        assert result.complete
        lengths.append(result.distance_m)
    assert lengths[1] >= lengths[0]


def test_uncoverable_cells_make_the_plan_cover_everything_it_can(tmp_path):
    """A sealed room (> done_unknown_cells free cells) cannot be seen: cover all the rest."""
    from conftest import maze_from_blocks

    blocks = ["##########", "#S.......#", "#.######.#", "#.#..#.#.#", "#.####.#.#", "#......#.#", "##########"]
    path = write_maze_png(maze_from_blocks(blocks), tmp_path / "sealed.png")
    ground_truth = load_maze_png(path)
    model, plan = cov.coverage_plan(ground_truth, PROTOCOL, **FAST)
    assert ground_truth.free_cell_count - len(model.cells) > PROTOCOL.done_unknown_cells
    assert model.slack() == 0
    assert not plan.complete and plan.remaining == 0
    tour = [tuple(model.world[v]) for v in plan.path]
    assert unseen_after(ground_truth, tour) == ground_truth.free_cell_count - len(model.cells)


def diagonal_pocket_map():
    """A 30 x 30-cell room and a 10 x 10-cell pocket that touches it only at one corner: the
    pocket is 8-connected to the start, yet no 4-connected ray (nor lattice edge) gets in."""
    from pipeline.world.maps import GroundTruthMap

    free = np.zeros((50, 50), dtype=bool)
    free[5:35, 5:35] = True
    free[35:45, 35:45] = True
    return GroundTruthMap(free=free, start_cell=(10, 10), cell_size=0.4, name="pocket")


def test_unobservable_free_cells_are_those_no_reachable_scan_reveals():
    from pipeline.evaluation.map_checks import unreachable_free_cells

    ground_truth = diagonal_pocket_map()
    protocol = Protocol(node_resolution=2.0, sensor_range=8.0, utility_range=4.0)
    assert unreachable_free_cells(ground_truth) == 0  # the corner joins them for 8-connectivity
    assert cm.unobservable_free_cells(ground_truth, protocol) == 100
    model = cm.CoverageModel(ground_truth, protocol)
    assert model.free_cell_count - len(model.cells) == 100


def test_a_maze_has_no_unobservable_free_cells(generated_maze):
    assert cm.unobservable_free_cells(generated_maze, Protocol()) == 0
