"""Min-max routes (pipeline/planners/team/min_max_routes.py) against brute force on small cases."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from pipeline.planners.team.min_max_routes import min_max_routes, route_lengths


def brute_force(distance: np.ndarray, robots: int) -> tuple[float, float]:
    """The best (longest route, sum of routes) over every order of the targets cut into `robots` routes."""
    targets = len(distance) - robots
    best = (np.inf, np.inf)
    for order in itertools.permutations(range(targets)):
        for cuts in itertools.combinations_with_replacement(range(targets + 1), robots - 1):
            bounds = (0, *cuts, targets)
            lengths = route_lengths(distance, [list(order[bounds[i] : bounds[i + 1]]) for i in range(robots)])
            best = min(best, (max(lengths), sum(lengths)))
    return best


def random_case(rng: np.random.Generator, robots: int, targets: int, asymmetric: bool = False) -> np.ndarray:
    points = rng.uniform(0, 100, (robots + targets, 2))
    distance = np.hypot(*(points[:, None, :] - points[None, :, :]).transpose(2, 0, 1))
    return distance * rng.uniform(1.0, 1.5, distance.shape) if asymmetric else distance


def assert_every_target_once(routes: list[list[int]], targets: int) -> None:
    assert sorted(t for route in routes for t in route) == list(range(targets))


@pytest.mark.parametrize("asymmetric", [False, True])
def test_exact_routes_match_brute_force(asymmetric):
    rng = np.random.default_rng(1 + asymmetric)
    for _ in range(40):
        robots, targets = int(rng.integers(1, 5)), int(rng.integers(0, 7))
        distance = random_case(rng, robots, targets, asymmetric)
        routes = min_max_routes(distance, robots)
        assert len(routes) == robots
        assert_every_target_once(routes, targets)
        lengths = route_lengths(distance, routes)
        longest, total = brute_force(distance, robots)
        assert max(lengths, default=0.0) == pytest.approx(longest, abs=1e-9)
        assert sum(lengths) == pytest.approx(total, abs=1e-9)


def test_ortools_routes_cover_every_target_near_the_optimum_and_repeat():
    pytest.importorskip("ortools")
    rng = np.random.default_rng(11)
    for _ in range(25):
        robots, targets = int(rng.integers(1, 4)), int(rng.integers(1, 7))
        distance = random_case(rng, robots, targets)
        routes = min_max_routes(distance, robots, time_limit_ms=2000, exact_max=0)
        assert_every_target_once(routes, targets)
        longest = max(route_lengths(distance, routes))
        optimum = brute_force(distance, robots)[0]
        assert optimum - 1e-6 <= longest <= 1.25 * optimum
        assert (
            min_max_routes(distance, robots, time_limit_ms=2000, exact_max=0) == routes
        )  # greedy descent: deterministic


@pytest.mark.parametrize("exact_max", [8, 0])
def test_two_robots_between_two_rooms_take_one_room_each(exact_max):
    if exact_max == 0:
        pytest.importorskip("ortools")
    # Both robots at x = 0; targets at x = -10, -12 (one room) and +10, +12 (the other).
    xs = np.array([0.0, 0.0, -10.0, 10.0, -12.0, 12.0])
    distance = np.abs(xs[:, None] - xs[None, :])
    routes = min_max_routes(distance, 2, exact_max=exact_max)
    rooms = sorted(sorted(route) for route in routes)
    assert rooms == [[0, 2], [1, 3]]
    assert max(route_lengths(distance, routes)) == pytest.approx(12.0)


def test_routes_are_open_and_ordered_from_the_start():
    xs = np.array([0.0, 30.0, 10.0, 20.0])  # one robot at 0, targets at 30, 10, 20
    distance = np.abs(xs[:, None] - xs[None, :])
    assert min_max_routes(distance, 1) == [[1, 2, 0]]


def test_a_target_one_robot_cannot_reach_goes_to_the_other():
    distance = np.array(
        [[0.0, 50.0, 5.0, np.inf], [50.0, 0.0, np.inf, 40.0], [5.0, np.inf, 0.0, np.inf], [np.inf, 40.0, np.inf, 0.0]]
    )
    assert min_max_routes(distance, 2) == [[0], [1]]


def test_more_robots_than_targets_leaves_some_without_a_route():
    xs = np.array([0.0, 5.0, 100.0, 4.0])  # robots at 0, 5, 100; one target at 4
    distance = np.abs(xs[:, None] - xs[None, :])
    assert min_max_routes(distance, 3) == [[], [0], []]


@pytest.mark.parametrize("bad", [dict(robots=0), dict(exact_max=11), dict(metaheuristic="tabu")])
def test_bad_arguments_are_refused(bad):
    arguments = dict(distance=np.zeros((3, 3)), robots=1) | bad
    with pytest.raises(ValueError):
        min_max_routes(**arguments)
