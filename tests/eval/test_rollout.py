"""eval/rollout.py: identical rollouts across policies, grid order, and argument errors."""

import numpy as np
import pandas as pd
import pytest

from eval.rollout import Episode, auto_workers, rollout, run_episode
from policies import PN, PN_THESIS

PERSON = ["time_s", "person_x_m", "person_y_m", "person_theta_rad", "person_v_mps"]


class StandStill:
    """A policy that never moves: as different from the laws as a policy can be."""

    name = "stand-still"

    def reset(self) -> None:
        pass

    def act(self, obs: np.ndarray) -> np.ndarray:
        return np.zeros(2, dtype=np.float32)


@pytest.fixture(scope="module")
def curve_seed_3() -> dict[str, Episode]:
    episodes = rollout(["pn:thesis", "gsmpn:tuned", StandStill()], ["curve"], [3])
    return {ep.policy: ep for ep in episodes}


def test_person_trajectory_is_identical_across_policies(curve_seed_3: dict[str, Episode]) -> None:
    pn, gsmpn, still = (curve_seed_3[k].log for k in ("pn:thesis", "gsmpn:tuned", "stand-still"))
    n = min(len(pn), len(gsmpn), len(still))  # episodes may end at different steps
    assert n > 50
    for other in (gsmpn, still):
        pd.testing.assert_frame_equal(pn[PERSON].iloc[:n], other[PERSON].iloc[:n])


def test_robots_differ_so_the_equality_above_is_not_vacuous(
    curve_seed_3: dict[str, Episode],
) -> None:
    pn, still = curve_seed_3["pn:thesis"].log, curve_seed_3["stand-still"].log
    assert still["robot_x_m"].iloc[-1] == still["robot_x_m"].iloc[0]
    assert pn["robot_x_m"].iloc[-1] != pn["robot_x_m"].iloc[0]


def test_detector_noise_draws_are_identical_across_policies(
    curve_seed_3: dict[str, Episode],
) -> None:
    # The detector result published at step k comes from frame k - 1 (1 frame of latency). Where
    # the person was visible to both robots in that frame, misses and occlusion bursts (the
    # detector's draws) must coincide, as must the box-centre jitter where the boxes agree.
    a, b = curve_seed_3["pn:thesis"].log, curve_seed_3["gsmpn:tuned"].log
    n = min(len(a), len(b))
    both_visible = (a["in_frame"].iloc[: n - 1].to_numpy() == 1) & (
        b["in_frame"].iloc[: n - 1].to_numpy() == 1
    )
    det_a = a["detected"].iloc[1:n].to_numpy()[both_visible]
    det_b = b["detected"].iloc[1:n].to_numpy()[both_visible]
    np.testing.assert_array_equal(det_a, det_b)
    assert 0 < det_a.sum() < det_a.size  # the seed has misses, so this compares real draws


def test_other_seed_gives_another_person() -> None:
    a = run_episode("pn:thesis", "random", 1).log
    b = run_episode("pn:thesis", "random", 2).log
    assert not np.allclose(a["person_y_m"].iloc[:30], b["person_y_m"].iloc[:30])


def test_same_policy_and_seed_give_bit_identical_logs() -> None:
    first = run_episode("mpn:thesis", "curve", 5).log
    second = run_episode("mpn:thesis", "curve", 5).log
    pd.testing.assert_frame_equal(first, second)


def test_rollout_returns_the_grid_in_policy_scenario_seed_order() -> None:
    episodes = rollout(["pn", "mpn"], ["straight", "curve"], [7, 8])
    assert [(e.policy, e.scenario, e.seed) for e in episodes] == [
        (p, s, seed)
        for p in ("pn:tuned", "mpn:tuned")
        for s in ("straight", "curve")
        for seed in (7, 8)
    ]
    assert all(e.log["policy"].iloc[0] == e.policy for e in episodes)


def test_policy_object_is_reset_for_each_episode() -> None:
    law = PN(PN_THESIS, name="my-pn")
    [a, b] = rollout([law], ["straight"], [4, 4])
    pd.testing.assert_frame_equal(a.log, b.log)


def test_reduce_replaces_episodes_by_their_reductions() -> None:
    steps = rollout(["pn"], ["straight"], [0, 1], reduce=_steps)
    assert steps == [run_episode("pn", "straight", s).steps for s in (0, 1)]


def _steps(episode: Episode) -> int:
    return episode.steps


@pytest.mark.slow
def test_process_pool_gives_the_same_episodes_as_in_process() -> None:
    here = rollout(["pn", "gsmpn"], ["curve"], [0, 1], workers=1)
    pooled = rollout(["pn", "gsmpn"], ["curve"], [0, 1], workers=2)
    for a, b in zip(here, pooled, strict=True):
        pd.testing.assert_frame_equal(a.log, b.log)


def test_unknown_policy_error_lists_the_known_names() -> None:
    with pytest.raises(ValueError, match=r"unknown policy 'lqr'; known names: .*gsmpn"):
        rollout(["pn", "lqr"], ["straight"], [0])


def test_unknown_scenario_error_lists_the_known_scenarios() -> None:
    with pytest.raises(ValueError, match=r"unknown scenario 'moonwalk'; known scenarios: .*curve"):
        rollout(["pn"], ["moonwalk"], [0])


@pytest.mark.parametrize("empty", ["policies", "scenarios", "seeds"])
def test_empty_grid_axis_is_rejected(empty: str) -> None:
    grid = {"policies": ["pn"], "scenarios": ["straight"], "seeds": [0], empty: []}
    with pytest.raises(ValueError, match=f"{empty} is empty"):
        rollout(grid["policies"], grid["scenarios"], grid["seeds"])


@pytest.mark.parametrize("seed", [-1, 1.5, "0"])
def test_bad_seed_is_rejected(seed: object) -> None:
    with pytest.raises(ValueError, match=r"seed=.* must be an integer >= 0"):
        rollout(["pn"], ["straight"], [seed])  # type: ignore[list-item]


@pytest.mark.parametrize("workers", [0, -2])
def test_workers_below_one_is_rejected(workers: int) -> None:
    with pytest.raises(ValueError, match=r"workers=.* must be an integer >= 1"):
        rollout(["pn"], ["straight"], [0], workers=workers)


def test_auto_workers_runs_small_grids_in_process() -> None:
    assert auto_workers(120) == 1
    assert auto_workers(1) == 1


def test_auto_workers_counts_a_learned_agents_episodes_as_dearer(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr("os.cpu_count", lambda: 2)
    assert auto_workers(1200) == 1  # a law on 100 seeds of every scenario: here
    assert auto_workers(1200, learned=1200) == 2  # an agent on them: a pool pays off
    assert auto_workers(160, learned=40) == 1  # make eval


def test_auto_workers_starts_a_pool_sooner_when_it_also_scores_the_episodes(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr("os.cpu_count", lambda: 2)
    assert auto_workers(600) == 1  # rollout alone: the pool's start is not paid back
    assert auto_workers(600, scored=True) == 2  # follow-eval run's logs and tables share it
    assert auto_workers(300, scored=True) == 1  # where the two took the same time
    assert auto_workers(160, learned=40, scored=True) == 1  # make eval


def test_the_grid_check_counts_the_learned_agents() -> None:
    from eval.rollout import _check_grid

    assert _check_grid(["ppo_law", "pn", "ppo_mecanum@mecanum"], ["straight"], [0])[0] == 2
    assert _check_grid(["pn", "gsmpn:tuned"], ["straight"], range(3))[0] == 0


def test_a_policy_runs_on_another_platform_by_name_with_its_own_columns() -> None:
    from eval.rollout import run_batch, run_episode
    from eval.steplog import COLUMNS

    batch = run_batch("pn@mecanum", "straight", [0, 1])
    single = run_episode("pn@mecanum", "straight", 1)
    log = batch[1].log
    assert batch[0].policy == single.policy == "pn:tuned@mecanum"
    assert {"action_vy_mps", "wheel_true_fl_radps", "duty_rr"} <= set(log.columns)
    assert "wheel_target_r_mps" not in log
    assert (log["action_vy_mps"].dropna() == 0.0).all()
    pd.testing.assert_frame_equal(log, single.log)
    assert list(run_batch("pn", "straight", [0])[0].log.columns) == list(COLUMNS)


def test_a_law_a_platform_cannot_run_is_refused_before_any_episode() -> None:
    from eval.rollout import rollout

    with pytest.raises(ValueError, match="commands vy_mps"):
        rollout(["holonomic@diff_drive"], ["straight"], [0])
    with pytest.raises(ValueError, match="platform='tank' is out of range"):
        rollout(["pn@tank"], ["straight"], [0])
