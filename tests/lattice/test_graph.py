import numpy as np
import pytest

from pipeline.lattice.graph import (
    NODE_FREE,
    NODE_OCCUPIED,
    REGION_BOUNDARY,
    REGION_EXPLORED,
    REGION_UNOBSERVED,
    LatticeGraph,
)
from pipeline.lattice.spec import LatticeSpec
from pipeline.lattice.visibility import nested_visible_counts, visible_counts
from pipeline.planners import make_planner
from pipeline.world.geometry import segment_is_known_free
from pipeline.world.protocol import Protocol
from pipeline.world.sensor import FREE, OCCUPIED, UNKNOWN
from pipeline.world.simulator import Episode, run_episode


def spec_for(ground_truth, protocol=Protocol()):
    return LatticeSpec.for_map(ground_truth, protocol)


def partial_episode(ground_truth, steps=12):
    """An episode part-way through, with the changed-cell batches the planner saw."""
    planner = make_planner("nearest_frontier")
    episode = Episode(ground_truth, Protocol())
    planner.reset(ground_truth, Protocol(), 0)
    batches = []
    for _ in range(steps):
        observation = episode.observe()
        batches.append(observation.changed)
        waypoints = planner.plan(observation)
        if not waypoints:
            break
        episode.move(waypoints[0])
    batches.append(episode.observe().changed)
    return episode, batches


def assert_same_graph(a: LatticeGraph, b: LatticeGraph):
    np.testing.assert_array_equal(a.node_state, b.node_state)
    np.testing.assert_array_equal(a.edge_valid, b.edge_valid)
    np.testing.assert_array_equal(a.frontier, b.frontier)
    np.testing.assert_array_equal(a.utility, b.utility)
    np.testing.assert_array_equal(a.region_labels(), b.region_labels())


def test_incremental_updates_equal_a_fresh_build(small_maze):
    episode, batches = partial_episode(small_maze)
    incremental = LatticeGraph(spec_for(small_maze))
    fresh = LatticeGraph(spec_for(small_maze))
    # Replay the same belief history: the incremental graph sees only changed cells.
    replay = Episode(small_maze, Protocol())
    incremental.update(replay.belief.grid, None)
    for point in episode.trajectory[1:]:
        replay.move(point)
        changed = replay.observe().changed
        incremental.update(replay.belief.grid, changed)
    fresh.update(episode.belief.grid, None)
    assert_same_graph(incremental, fresh)
    assert len(batches) > 3


def test_a_graph_without_region_tracking_differs_only_in_its_regions(small_maze):
    """Rollout copies turn region labels off: nodes, edges, frontier and utilities stay exact."""
    episode, _ = partial_episode(small_maze)
    graphs = {}
    for track in (True, False):
        graph = LatticeGraph(spec_for(small_maze))
        graph.update(Episode(small_maze, Protocol()).belief.grid, None)
        graph.track_regions = track
        replay = Episode(small_maze, Protocol())
        for point in episode.trajectory[1:]:
            replay.move(point)
            graph.update(replay.belief.grid, replay.observe().changed)
        graphs[track] = graph
    tracked, untracked = graphs[True], graphs[False]
    for name in ("node_state", "edge_valid", "frontier", "utility"):
        np.testing.assert_array_equal(getattr(tracked, name), getattr(untracked, name))
    assert tracked.region_observed.sum() > untracked.region_observed.sum()


def test_neighbours_follow_the_edges_as_the_graph_grows(small_maze):
    """Neighbour lists are cached per graph change: each update must be seen."""
    episode, _ = partial_episode(small_maze, steps=6)
    graph = LatticeGraph(spec_for(small_maze))
    replay = Episode(small_maze, Protocol())
    graph.update(replay.belief.grid, None)
    for point in episode.trajectory[1:]:
        edges = graph.edges
        for node in np.unique(edges):
            expected = np.sort(np.concatenate([edges[edges[:, 0] == node, 1], edges[edges[:, 1] == node, 0]]))
            np.testing.assert_array_equal(graph.neighbours(int(node)), expected)
        replay.move(point)
        graph.update(replay.belief.grid, replay.observe().changed)
    assert graph.neighbours(int(np.setdiff1d(np.arange(graph.node_count), graph.edges)[0])).size == 0


def test_edges_are_exactly_the_known_free_segments(small_maze):
    episode, _ = partial_episode(small_maze, steps=8)
    graph = LatticeGraph(spec_for(small_maze))
    graph.update(episode.belief.grid, None)
    free = episode.belief.grid == FREE
    for (a, b), valid in zip(graph.edge_nodes, graph.edge_valid):
        ca, cb = tuple(graph.node_cells[a]), tuple(graph.node_cells[b])
        assert valid == segment_is_known_free(free, ca, cb)
    # Only 5x5-window neighbours are candidates.
    delta = np.abs(graph.node_ij[graph.edge_nodes[:, 0]] - graph.node_ij[graph.edge_nodes[:, 1]])
    assert delta.max() == 2 and (delta.sum(axis=1) > 0).all()


def test_node_states_follow_the_belief(small_maze):
    episode, _ = partial_episode(small_maze, steps=5)
    graph = LatticeGraph(spec_for(small_maze))
    graph.update(episode.belief.grid, None)
    values = episode.belief.grid.reshape(-1)[graph.node_flat]
    assert ((graph.node_state == NODE_FREE) == (values == FREE)).all()
    assert ((graph.node_state == NODE_OCCUPIED) == (values == OCCUPIED)).all()
    assert set(graph.free_nodes) == set(np.nonzero(values == FREE)[0])


def test_shortest_paths_follow_valid_edges(small_maze):
    episode, _ = partial_episode(small_maze, steps=10)
    graph = LatticeGraph(spec_for(small_maze))
    graph.update(episode.belief.grid, None)
    source = graph.nearest_node(episode.position)
    dist, pred = graph.shortest_paths(source)
    reachable = np.nonzero(np.isfinite(dist))[0]
    assert len(reachable) > 5
    target = int(reachable[np.argmax(dist[reachable])])
    path = graph.path_from_predecessors(pred, target)
    assert path[0] == source and path[-1] == target
    valid = {tuple(sorted(e)) for e in graph.edges.tolist()}
    length = 0.0
    for a, b in zip(path, path[1:]):
        assert tuple(sorted((a, b))) in valid
        length += float(np.hypot(*(graph.node_world[b] - graph.node_world[a])))
    assert length == pytest.approx(dist[target])


def test_shortest_paths_equal_scipys_undirected_search(small_maze):
    """The directed search on `search_matrix` gives the distances and, among equally long paths,
    the predecessors of scipy's undirected search on the adjacency: every planner's routes rest
    on those ties."""
    from scipy.sparse.csgraph import dijkstra

    episode, batches = partial_episode(small_maze, steps=14)
    graph = LatticeGraph(spec_for(small_maze))
    replay = Episode(small_maze, Protocol())
    graph.update(replay.belief.grid, None)
    searched = 0
    for point in episode.trajectory[1:]:
        replay.move(point)
        graph.update(replay.belief.grid, replay.observe().changed)
        for source in graph.free_nodes[::3]:
            dist, pred = graph.shortest_paths(int(source))
            want_dist, want_pred = dijkstra(
                graph.adjacency(), directed=False, indices=int(source), return_predecessors=True
            )
            np.testing.assert_array_equal(dist, want_dist)
            np.testing.assert_array_equal(pred, want_pred)
            searched += 1
    assert searched > 50


def test_a_copied_graph_shares_its_geometry_and_owns_its_state(small_maze):
    import copy

    episode, _ = partial_episode(small_maze, steps=6)
    graph = LatticeGraph(spec_for(small_maze))
    graph.update(episode.belief.grid, None)
    clone = copy.deepcopy(graph)
    assert clone.edge_nodes is graph.edge_nodes and clone._walk_rows is graph._walk_rows
    assert_same_graph(clone, graph)
    for name in ("node_state", "utility", "frontier", "edge_valid", "region_observed"):
        assert getattr(clone, name) is not getattr(graph, name)
    before = graph.edge_valid.copy(), graph.utility.copy()
    clone.update(small_maze.free.astype(np.uint8) * FREE, None)  # everything known free: the clone's state moves
    assert clone.edge_valid.sum() > before[0].sum()
    np.testing.assert_array_equal(graph.edge_valid, before[0])
    np.testing.assert_array_equal(graph.utility, before[1])


def test_utility_counts_visible_frontier_cells():
    belief = np.full((60, 60), OCCUPIED, dtype=np.uint8)
    belief[10:50, 10:30] = FREE  # a known room ...
    belief[:, 30:] = UNKNOWN  # ... whose right edge borders unknown space
    spec = LatticeSpec((60, 60), (20, 30), 0.4, 4.0, 10.0, 20.0)
    graph = LatticeGraph(spec)
    graph.update(belief, None)
    assert graph.frontier.sum() == 40 and graph.frontier[10:50, 29].all()
    near = graph.node_id(0, 0)  # cell (20, 30): every frontier cell is within 25 cells
    assert graph.utility[near] == 40
    corner = graph.node_id(-2, -2)  # cell (0, 10): occupied, so no utility
    assert graph.utility[corner] == 0
    belief[:, 30:] = OCCUPIED  # close the room: no frontier left
    graph.update(belief, np.arange(60 * 60).reshape(60, 60)[:, 30:].ravel())
    assert graph.utility[near] == 0 and not graph.frontier.any()


def test_regions_are_labelled_and_unobserved_centroids_placed(small_maze):
    episode, _ = partial_episode(small_maze, steps=3)
    graph = LatticeGraph(spec_for(small_maze))
    graph.update(episode.belief.grid, None)
    labels = graph.region_labels()
    assert {REGION_BOUNDARY, REGION_UNOBSERVED} <= set(labels.ravel().tolist())
    centroids = graph.unobserved_centroids()
    assert len(centroids) == int((labels == REGION_UNOBSERVED).sum())
    # A fully explored map has no boundary and no unobserved region left near the robot.
    result = run_episode(small_maze, make_planner("nearest_frontier"), Protocol())
    assert result.complete
    done = Episode(small_maze, Protocol())
    for point in result.trajectory[1:]:
        done.move(point)
    graph.update(done.belief.grid, None)
    assert (graph.region_labels() == REGION_EXPLORED).sum() >= (labels == REGION_EXPLORED).sum()


def test_lattice_at_real_robot_resolution():
    spec = LatticeSpec((100, 150), (7, 11), 0.2, 1.0, 5.0, 8.0)
    graph = LatticeGraph(spec)
    cells = graph.node_cells
    assert ((cells[:, 0] - 7) % 5 == 0).all() and ((cells[:, 1] - 11) % 5 == 0).all()
    assert cells[:, 0].min() == 2 and cells[:, 0].max() == 147
    assert graph.node_count == len(graph.lattice_i) * len(graph.lattice_j)


def reference_visible_counts(
    free: np.ndarray, targets: np.ndarray, origins: np.ndarray, range_cells: float
) -> np.ndarray:
    """The ray-fan count written plainly in NumPy: every ray's cells up to its first non-free cell."""
    from pipeline.lattice.visibility import UTILITY_ANGLES
    from pipeline.world.geometry import ray_table

    rows, cols = free.shape
    table = ray_table(0, 0, range_cells, UTILITY_ANGLES)
    counts = []
    for ox, oy in origins:
        xs, ys = ox + table.offsets[..., 0], oy + table.offsets[..., 1]
        inside = table.valid & (xs >= 0) & (xs < cols) & (ys >= 0) & (ys < rows)
        open_cell = inside & free[np.clip(ys, 0, rows - 1), np.clip(xs, 0, cols - 1)]
        reach = np.cumprod(open_cell, axis=1).astype(bool)
        cells = {(int(x), int(y)) for x, y in zip(xs[reach], ys[reach])}
        counts.append(sum(bool(targets[y, x]) for x, y in cells))
    return np.array(counts, dtype=np.int64)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_visible_counts_match_the_plain_ray_walk(seed):
    rng = np.random.default_rng(seed)
    free = rng.random((90, 70)) < rng.uniform(0.6, 0.95)
    targets = (rng.random((90, 70)) < 0.2).astype(np.uint8)  # any truthy dtype
    origins = rng.integers(-4, 94, size=(40, 2))  # some outside the grid
    got = visible_counts(free, targets, origins, 25.0)
    assert got.dtype == np.int64 and got.shape == (40,)
    assert (got == reference_visible_counts(free, targets.astype(bool), origins, 25.0)).all()
    assert got.max() > 0
    assert visible_counts(free, targets, origins[:0], 25.0).shape == (0,)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_nested_visible_counts_equal_three_separate_fans(seed):
    rng = np.random.default_rng(seed)
    outer = rng.random((90, 70)) < 0.9
    inner = outer & (rng.random((90, 70)) < 0.8)
    first, second, third = rng.random((3, 90, 70)) < [[[0.1]], [[0.3]], [[0.2]]]
    origins = rng.integers(-4, 94, size=(40, 2))  # some outside the grid
    got = nested_visible_counts(outer, (first, second), inner, third, origins, 25.0)
    assert got.shape == (40, 3) and got.min(axis=0).min() >= 0 and (got.max(axis=0) > 0).all()
    assert (got[:, 0] == reference_visible_counts(outer, first, origins, 25.0)).all()
    assert (got[:, 1] == reference_visible_counts(outer, second, origins, 25.0)).all()
    assert (got[:, 2] == reference_visible_counts(inner, third, origins, 25.0)).all()
    assert nested_visible_counts(outer, (first, second), inner, third, origins[:0], 25.0).shape == (0, 3)
    with pytest.raises(ValueError, match="inner_free must lie inside outer_free"):
        nested_visible_counts(inner, (first, second), outer, third, origins, 25.0)
    with pytest.raises(ValueError, match="differ in shape"):
        nested_visible_counts(outer, (first, second[:-1]), inner, third, origins, 25.0)
