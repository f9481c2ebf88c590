"""bench/agents.py: the shipped agent's rows of make bench, on a few lanes."""

import pytest

import bench.agents


def test_the_agent_has_a_row_and_its_predict_baseline(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(bench.agents, "LANES", 8)
    (name, rate, ratio), (base_name, baseline, one) = bench.agents.bench_agents(quick=True)
    assert name == f"{bench.agents.AGENT} network, 8 lanes"
    assert base_name == f"  {bench.agents.AGENT}, SB3's predict path"
    assert rate > 0.0
    assert baseline > 0.0
    assert ratio == f"{rate / baseline:.2f}x"
    assert one == "1x (baseline)"
