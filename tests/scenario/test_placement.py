"""Station placement on a generated network: spacing checked by road, errors are clear."""

from __future__ import annotations

import numpy as np
import pytest

from evcd.scenario.placement import Anchor, candidate_edges, place_stations
from evcd.scenario.routing import RoadGraph, distance_matrix


def _pairwise(net, stations):
    graph = RoadGraph.from_net(net)
    d = distance_matrix(graph, [s.edge for s in stations], [(s.start_pos + s.end_pos) / 2 for s in stations])
    return np.minimum(d, d.T)


@pytest.mark.parametrize("k,spacing", [(3, 1000.0), (5, 700.0)])
def test_spacing_is_met_by_road(grid_net, k, spacing):
    stations = place_stations(grid_net, k, spacing, np.random.default_rng(0))
    assert len(stations) == k
    assert len({s.edge for s in stations}) == k
    d = _pairwise(grid_net, stations)
    off_diag = d[~np.eye(k, dtype=bool)]
    assert off_diag.min() >= spacing
    for s in stations:
        lane = grid_net.getLane(s.lane)
        assert 0 <= s.start_pos < s.end_pos <= lane.getLength()
        assert s.power_w == 100_000 and s.points == 2


def test_same_seed_same_placement(grid_net):
    a = place_stations(grid_net, 4, 600.0, np.random.default_rng(3), max_candidates=50)
    b = place_stations(grid_net, 4, 600.0, np.random.default_rng(3), max_candidates=50)
    assert a == b


def test_spread_beats_random(grid_net):
    """Greedy p-median placement serves the network better than random candidates do."""
    graph = RoadGraph.from_net(grid_net)
    placed = place_stations(grid_net, 3, 500.0, np.random.default_rng(0))

    def mean_nearest(edges):
        return np.min(np.stack([graph.distances_to(e) for e in edges]), axis=0).mean()

    rng = np.random.default_rng(1)
    cands = candidate_edges(grid_net, graph)
    random_costs = [mean_nearest(rng.choice(cands, size=3, replace=False)) for _ in range(20)]
    assert mean_nearest([s.edge for s in placed]) < np.median(random_costs)


def test_anchor_needs_a_geo_referenced_network(grid_net):
    # netgenerate writes no projection: an anchor at a longitude/latitude cannot be placed
    with pytest.raises(ValueError, match="geo-reference"):
        place_stations(grid_net, 2, 100.0, np.random.default_rng(0), anchors=[Anchor("Mall", 103.7, 1.34)])


def test_impossible_spacing_is_a_clear_error(grid_net):
    with pytest.raises(ValueError, match=r"min_spacing=50000"):
        place_stations(grid_net, 3, 50_000.0, np.random.default_rng(0))


@pytest.mark.parametrize(
    "kwargs,match",
    [({"k": 0, "min_spacing": 10.0}, "k=0"), ({"k": 2, "min_spacing": -1.0}, "min_spacing=-1")],
)
def test_bad_arguments(grid_net, kwargs, match):
    with pytest.raises(ValueError, match=match):
        place_stations(grid_net, rng=np.random.default_rng(0), **kwargs)
