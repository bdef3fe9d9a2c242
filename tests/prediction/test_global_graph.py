import numpy as np
import pytest
from scipy.sparse.csgraph import connected_components

from pipeline.lattice.graph import NODE_UNKNOWN, REGION_BOUNDARY, REGION_EXPLORED, REGION_UNOBSERVED
from pipeline.planners import make_planner
from pipeline.planners.wrapper import innermost
from pipeline.prediction.global_graph import (
    CENTROID,
    KNOWN,
    PREDICTED,
    GlobalGraph,
    GlobalGraphConfig,
    RegionEvaluationConfig,
    region_scores,
)
from pipeline.prediction.node_image import ground_truth_states, node_states_image, observed_node_states
from pipeline.prediction.node_predictor import (
    NodePredictor,
    NodePredictorConfig,
    drop_small_components,
    pad_to_multiple,
)
from pipeline.world.geometry import walk_cells
from pipeline.world.protocol import Protocol
from pipeline.world.sensor import OCCUPIED
from pipeline.world.simulator import Episode


@pytest.fixture(scope="module")
def partial(small_maze):
    planner = innermost(make_planner("nearest_frontier"))
    episode = Episode(small_maze, Protocol())
    planner.reset(small_maze, Protocol(), 0)
    for _ in range(4):
        episode.move(planner.plan(episode.observe())[0])
    graph = planner.update_graph(episode.observe())
    return small_maze, episode, planner, graph


def oracle_inpainter(graph, ground_free):
    """A stand-in network that knows the ground-truth node image."""
    truth = node_states_image(graph, ground_truth_states(graph, ground_free))
    padded, _ = pad_to_multiple(truth, 8, 128)
    return lambda image: (padded == 255).astype(np.float32)


def test_predictor_returns_unknown_nodes_that_are_free(partial):
    ground_truth, episode, _, graph = partial
    predicted = NodePredictor(oracle_inpainter(graph, ground_truth.free)).predict(graph)
    assert predicted.size > 0
    assert (graph.node_state[predicted] == NODE_UNKNOWN).all()
    assert ground_truth.free.reshape(-1)[graph.node_flat[predicted]].all()


def test_predictor_pads_to_the_stride_and_checks_the_output_shape(partial):
    _, _, _, graph = partial
    seen = []
    NodePredictor(lambda image: seen.append(image.copy()) or np.zeros(image.shape)).predict(graph)
    image = seen[0]
    assert all(s % 8 == 0 for s in image.shape)
    rows, cols = graph.lattice_shape
    r0, c0 = (image.shape[0] - rows) // 2, (image.shape[1] - cols) // 2
    inside = np.zeros(image.shape, dtype=bool)
    inside[r0 : r0 + rows, c0 : c0 + cols] = True
    assert (~inside).any() and (image[~inside] == 0).all()  # outside the map is drawn as obstacle
    assert (image[inside] == node_states_image(graph, observed_node_states(graph.belief, graph)).reshape(-1)).all()
    with pytest.raises(ValueError, match="shape"):
        NodePredictor(lambda image: np.zeros((3, 3))).predict(graph)


def test_isolated_predictions_are_dropped():
    predicted = np.zeros((8, 8), dtype=bool)
    predicted[0, 0] = True
    predicted[5, 5:8] = True
    kept = drop_small_components(predicted, np.zeros_like(predicted), 3)
    assert not kept[0, 0] and kept[5, 5:8].all()


def test_region_scores_prefer_near_regions_with_frontiers():
    labels = np.array([[REGION_BOUNDARY, REGION_UNOBSERVED, REGION_EXPLORED]])
    centroids = np.array([[[10.0, 0.0], [50.0, 0.0], [90.0, 0.0]]])
    scores = region_scores(labels, centroids, np.array([[12.0, 0.0]]), np.array([0.0, 0.0]), RegionEvaluationConfig())
    assert scores[0, 0] > scores[0, 1] and np.isnan(scores[0, 2])


def test_global_graph_joins_predictions_without_crossing_known_obstacles(partial):
    ground_truth, episode, planner, graph = partial
    predicted = NodePredictor(oracle_inpainter(graph, ground_truth.free), NodePredictorConfig(min_component=1)).predict(
        graph
    )
    global_graph = GlobalGraph(graph, GlobalGraphConfig(region=RegionEvaluationConfig(keep_share=1.0)))
    global_graph.update(episode.belief.grid, episode.position, predicted, planner.visited)
    types = np.bincount(global_graph.types, minlength=3)
    assert types[KNOWN] == len(graph.free_nodes) and types[PREDICTED] > 0
    assert (global_graph.utility[global_graph.types != KNOWN] == 0).all()
    assert (global_graph.utility >= 0).all()
    coo = global_graph.adjacency.tocoo()
    cells = graph.spec.world_to_cell(global_graph.positions)
    for a, b in zip(coo.row, coo.col):
        if global_graph.types[a] == KNOWN and global_graph.types[b] == KNOWN:
            continue
        walks = [walk_cells(tuple(cells[a]), tuple(cells[b])), walk_cells(tuple(cells[b]), tuple(cells[a]))]
        assert any((episode.belief.grid[w[:, 1], w[:, 0]] != OCCUPIED).all() for w in walks)
    assert connected_components(global_graph.adjacency, directed=False)[0] <= 2


def test_region_evaluation_trims_far_predictions(partial):
    ground_truth, episode, planner, graph = partial
    predicted = NodePredictor(oracle_inpainter(graph, ground_truth.free), NodePredictorConfig(min_component=1)).predict(
        graph
    )
    everything = GlobalGraph(graph, GlobalGraphConfig(use_region_evaluation=False))
    everything.update(episode.belief.grid, episode.position, predicted)
    filtered = GlobalGraph(
        graph, GlobalGraphConfig(region=RegionEvaluationConfig(keep_share=0.2, centroid_density=0.0))
    )
    filtered.update(episode.belief.grid, episode.position, predicted)
    assert (filtered.types == PREDICTED).sum() < (everything.types == PREDICTED).sum()
    # With no density bar, every unobserved region whose predictions were all dropped stands in as one
    # centroid node: its predicted node nearest the region's centre.
    node_region = graph.region_of_cells(graph.node_cells)
    kept_regions = {tuple(node_region[n]) for n in filtered.lattice_ids[filtered.types == PREDICTED]}
    labels, centroids = graph.region_labels(), graph.region_centroids()
    dropped_unobserved = {tuple(node_region[n]) for n in predicted} - kept_regions
    dropped_unobserved = {r for r in dropped_unobserved if labels[r] == REGION_UNOBSERVED}
    expected = []
    for region in dropped_unobserved:
        members = [n for n in predicted if tuple(node_region[n]) == region]
        nearest = min(members, key=lambda n: np.hypot(*(graph.node_world[n] - centroids[region])))
        expected.append(tuple(graph.node_world[nearest]))
    expected = np.array(sorted(expected)).reshape(-1, 2)
    got = filtered.positions[filtered.types == CENTROID]
    assert len(expected) > 0
    assert np.allclose(got[np.lexsort(got.T[::-1])], expected)
    # each centroid node sits on a predicted node of its own region
    predicted_xy = {tuple(xy) for xy in graph.node_world[predicted]}
    assert all(tuple(xy) in predicted_xy for xy in got)


def test_features_are_padded_with_a_mask(partial):
    ground_truth, episode, planner, graph = partial
    global_graph = GlobalGraph(graph, GlobalGraphConfig(max_nodes=64))
    global_graph.update(episode.belief.grid, episode.position, None, planner.visited)
    features, mask, robot_row = global_graph.features(episode.position)
    assert features.shape == (64, 7) and mask.sum() == min(64, global_graph.node_count)
    assert np.allclose(features[robot_row, :2], 0.0)
    assert (features[~mask] == 0).all()
    assert features[mask, 3].any()  # a guidepost path exists while frontiers remain


def test_guidepost_leads_to_the_nearest_unvisited_useful_node(partial):
    ground_truth, episode, planner, graph = partial
    global_graph = GlobalGraph(graph, GlobalGraphConfig(max_nodes=512))
    global_graph.update(episode.belief.grid, episode.position, None, planner.visited)
    robot = global_graph.nearest(episode.position)
    global_graph.utility[robot] = 50.0  # the robot's own node sees frontier: it must not be the target
    features, mask, robot_row = global_graph.features(episode.position)
    order = global_graph.row_order(np.asarray(episode.position, dtype=np.float64))
    on_path = order[features[: len(order), 3] > 0]
    dist, _ = global_graph.shortest_paths(robot)
    useful = np.nonzero(
        ~global_graph.visited & np.isfinite(dist) & (global_graph.utility >= global_graph.config.guidepost_min_utility)
    )[0]
    target = useful[np.argmin(dist[useful])]
    assert global_graph.visited[robot] and target != robot
    assert robot in on_path and target in on_path and len(on_path) >= 2  # a path, not the robot's node alone


def test_features_keep_the_nearest_nodes_with_their_flags(partial):
    """Trimmed to max_nodes, the rows are the nearest nodes, nearest first, and carry their visited flags."""
    ground_truth, episode, planner, graph = partial
    global_graph = GlobalGraph(graph, GlobalGraphConfig(max_nodes=6))
    global_graph.update(episode.belief.grid, episode.position, None, planner.visited)
    assert global_graph.node_count > 6 and global_graph.visited.sum() >= 2
    features, mask, robot_row = global_graph.features(episode.position)
    robot_xy = np.asarray(episode.position, dtype=np.float64)
    distance = np.hypot(*(global_graph.positions - robot_xy).T)
    nearest = np.argsort(distance, kind="stable")[:6]
    scale = global_graph.config.position_scale_nodes * graph.spec.node_resolution
    assert mask.all() and robot_row == 0
    assert np.allclose(features[:, :2] * scale, global_graph.positions[nearest] - robot_xy, atol=1e-4)
    assert (features[:, 4] == global_graph.visited[nearest]).all() and features[:, 4].any()
    assert (np.diff(np.hypot(*(features[:, :2].T))) >= -1e-6).all()


def test_predictor_binarises_at_tau(partial):
    """P(free) >= tau is predicted, below it is not (graded probabilities, not just 0 and 1)."""
    _, _, _, graph = partial
    predictor, probability, _ = graded_predictor(graph, threshold=0.5)
    predicted = predictor.predict(graph)
    unknown = np.nonzero(observed_node_states(graph.belief, graph) == NODE_UNKNOWN)[0]  # walls inferred: not unknown
    assert set(predicted) == set(unknown[probability[unknown] >= 0.5])
    assert (probability[predicted] >= 0.5).all() and (probability[predicted] == 0.5).any()


def graded_predictor(graph, **config):
    """A stand-in network giving every unknown node P(free) 0.3, 0.5 or 0.7, in every region."""
    rows, cols = graph.lattice_shape
    levels = np.array([0.3, 0.5, 0.7], dtype=np.float32)
    graded = levels[(np.arange(rows)[:, None] + np.arange(cols)[None, :]) % 3]
    padded, _ = pad_to_multiple(graded, 8, 0)
    calls = []
    predictor = NodePredictor(lambda image: calls.append(1) or padded, NodePredictorConfig(min_component=1, **config))
    return predictor, graded.reshape(-1), calls


def test_predictor_gives_graph_and_counted_nodes_from_one_inpainting(partial):
    _, _, _, graph = partial
    predictor, probability, calls = graded_predictor(graph, threshold=0.7, count_threshold=0.5)
    predicted, counted = predictor.predict_with_counted(graph)
    assert len(calls) == 1
    unknown = np.nonzero(observed_node_states(graph.belief, graph) == NODE_UNKNOWN)[0]
    assert set(predicted) == set(unknown[probability[unknown] >= 0.7])
    assert set(counted) == set(unknown[probability[unknown] >= 0.5])
    assert set(predicted) < set(counted)
    # without a count tau of its own the counted nodes are the graph's
    same, counted_same = graded_predictor(graph, threshold=0.7, count_threshold=None)[0].predict_with_counted(graph)
    assert counted_same is same


def test_utility_boost_counts_the_counted_nodes_and_the_graph_holds_only_the_predicted(partial):
    """The count tau feeds N_u only: graph nodes, edges and features come from the graph's tau."""
    _, episode, planner, graph = partial
    predictor, _, _ = graded_predictor(graph, threshold=0.7, count_threshold=0.5)
    predicted, counted = predictor.predict_with_counted(graph)
    config = GlobalGraphConfig(region=RegionEvaluationConfig(keep_share=1.0, centroid_density=1.1))
    narrow, split, broad = (GlobalGraph(graph, config) for _ in range(3))
    narrow.update(episode.belief.grid, episode.position, predicted, planner.visited)
    split.update(episode.belief.grid, episode.position, predicted, planner.visited, counted)
    broad.update(episode.belief.grid, episode.position, counted, planner.visited)
    assert np.array_equal(split.lattice_ids, narrow.lattice_ids) and np.array_equal(split.types, narrow.types)
    assert (split.adjacency != narrow.adjacency).nnz == 0
    assert np.allclose(split.utility[split.types == KNOWN], broad.utility[broad.types == KNOWN])
    assert (split.utility > narrow.utility + 1e-9).any()  # more counted nodes, a larger boost somewhere
