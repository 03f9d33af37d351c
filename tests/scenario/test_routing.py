"""Road distances against SUMO's own router (sumolib) on a real generated network."""

from __future__ import annotations

import numpy as np
import pytest

from evcd.scenario.routing import RoadGraph, distance_matrix


def test_distances_match_sumolib_shortest_path(grid_net):
    graph = RoadGraph.from_net(grid_net)
    rng = np.random.default_rng(0)
    for _ in range(10):
        a, b = rng.choice(graph.edge_ids, size=2, replace=False)
        route, cost = grid_net.getShortestPath(grid_net.getEdge(a), grid_net.getEdge(b))
        assert route is not None
        # sumolib's cost includes the target edge; ours stops at its start
        expected = cost - grid_net.getEdge(b).getLength()
        assert graph.distances_from(a)[graph.index[b]] == pytest.approx(expected)
        assert graph.distances_to(b)[graph.index[a]] == pytest.approx(expected)


def test_distance_matrix_offsets(grid_net):
    graph = RoadGraph.from_net(grid_net)
    a, b = graph.edge_ids[0], graph.edge_ids[5]
    plain = distance_matrix(graph, [a, b])
    moved = distance_matrix(graph, [a, b], offsets=[10.0, 30.0])
    assert moved[0, 1] == pytest.approx(plain[0, 1] - 10 + 30)
    assert moved[1, 0] == pytest.approx(plain[1, 0] - 30 + 10)
    assert np.all(np.diag(moved) == 0)


def test_unknown_edge_is_a_clear_error(grid_net):
    graph = RoadGraph.from_net(grid_net)
    with pytest.raises(ValueError, match="no_such_edge"):
        graph.distances_from("no_such_edge")
