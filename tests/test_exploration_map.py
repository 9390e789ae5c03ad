"""studies/exploration/exploration_map.py, network by network: ranks, Spearman's rho and the means either side."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture
def tool(load_tool):
    return load_tool("studies/exploration/exploration_map")


def test_ranks_share_ties(tool):
    ranks = tool._ranks(np.array([3.0, 1.0, 3.0, 2.0]))
    np.testing.assert_array_equal(ranks, [3.5, 1.0, 3.5, 2.0])


def test_summary_of_networks_either_side_of_the_field(tool):
    # damping falls as the loss rises, monotonically but not linearly: Spearman's rho is exactly -1
    damping = [2.0, 5.0, 10.0, 20.0, 40.0]
    lost = [0.6, 0.5, 0.2, 0.05, 0.01]
    out = [0.5, 0.5, 0.1, 0.0, 0.0]
    points = [{"damping": d, "success_lost": c, "out": o} for d, c, o in zip(damping, lost, out, strict=True)]
    s = tool.network_summary(points)
    assert s["networks"] == 5 and s["below"] == 3  # 2, 5 and 10 lie below the field's 15.9
    assert s["rho_lost"] == pytest.approx(-1.0)
    assert s["rho_out"] == pytest.approx(np.corrcoef([1, 2, 3, 4, 5], [4.5, 4.5, 3, 1.5, 1.5])[0, 1])
    assert s["lost_below"] == pytest.approx(np.mean(lost[:3]))
    assert s["lost_above"] == pytest.approx(np.mean(lost[3:]))
    assert s["out_above"] == 0.0
