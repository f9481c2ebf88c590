"""policies.adapt.at_period: a law differentiates over the period its observations arrive at."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from policies import PN, at_period, make_policy
from policies.gsmpn import GSMPN
from policies.pid_line import PIDLine


@pytest.mark.parametrize("name", ["mpn:thesis", "gsmpn:thesis", "gsmpn-listing", "pid"])
def test_a_law_with_a_period_gets_a_copy_at_the_loops(name: str) -> None:
    task = "line_trace" if name == "pid" else None
    law = make_policy(name, task) if task else make_policy(name)
    built = law.params.dt_s
    fast = at_period(law, built / 2)
    assert fast is not law
    assert fast.params.dt_s == built / 2
    assert fast.name == law.name
    assert law.params.dt_s == built  # the law given is left as it was
    assert fast.params == replace(law.params, dt_s=built / 2)  # nothing else changed


def test_the_offset_rate_is_taken_over_the_new_period() -> None:
    # o goes 0 -> 10 px in one step; at 0.05 s that is 200 px/s, not 100 px/s: the rate term
    # lambda * rate doubles against the same law at 0.1 s.
    law = make_policy("mpn:thesis")
    fast = at_period(law, 0.05)
    turns = {}
    for key, policy in (("slow", law), ("fast", fast)):
        policy.reset()
        policy.act(np.array([2.0, 0.0], np.float32))
        turns[key] = float(policy.act(np.array([2.0, 10.0], np.float32))[1])
    p = law.params
    pn_part = -p.nav_n * p.kw_rad_per_s_px * 10.0 / 2.0
    assert turns["slow"] == pytest.approx(pn_part - p.lambda_rad_per_px * 100.0, rel=1e-5)
    assert turns["fast"] == pytest.approx(pn_part - p.lambda_rad_per_px * 200.0, rel=1e-5)


def test_policies_without_a_period_and_laws_at_it_are_returned_as_they_are() -> None:
    pn = make_policy("pn:thesis")
    assert isinstance(pn, PN)
    assert at_period(pn, 0.05) is pn
    gs = make_policy("gsmpn")
    assert isinstance(gs, GSMPN)
    assert at_period(gs, gs.params.dt_s) is gs
    assert at_period(make_policy("coordinate", "line_trace"), 0.05) is not None


def test_a_period_out_of_the_laws_range_is_refused_naming_it() -> None:
    pid = make_policy("pid", "line_trace")
    assert isinstance(pid, PIDLine)
    with pytest.raises(ValueError, match=r"dt_s"):
        at_period(pid, 2.0)


def test_the_evaluation_runs_a_law_at_the_envs_period() -> None:
    """gsmpn:thesis in an env stepping every 0.05 s acts as the same law built at 0.05 s, one
    episode at a time and batched, by name or given as an object (before, it divided every
    rate by its own 0.1 s)."""
    from eval.rollout import run_batch, run_episode

    config = {"episode": {"control_dt_s": 0.05}}
    columns = ["action_v_mps", "action_w_radps"]
    thesis = make_policy("gsmpn:thesis").params
    by_hand = GSMPN(replace(thesis, dt_s=0.05), "gsmpn:thesis")
    reference = run_episode(by_hand, "curve", 3, config=config).log[columns].to_numpy()
    runs = {
        "by name": run_episode("gsmpn:thesis", "curve", 3, config=config),
        "an object at 0.1 s": run_episode(GSMPN(thesis, "gsmpn:thesis"), "curve", 3, config=config),
        "batched": run_batch("gsmpn:thesis", "curve", [3], config=config)[0],
    }
    for how, episode in runs.items():
        np.testing.assert_array_equal(episode.log[columns].to_numpy(), reference, err_msg=how)
