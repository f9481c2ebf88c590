"""eval/tuning/: follow-tune's search spaces, driver, held-out check and command line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import optuna
import pytest
from optuna.trial import TrialState

from eval.tuning import (
    Candidate,
    LawObjective,
    SearchConfig,
    choose,
    open_study,
    run_search,
    rungs,
    verdict,
)
from eval.tuning.cli import main
from eval.tuning.holdout import MIN_GAIN
from eval.tuning.objective import EVAL_SEEDS, HOLDOUT_SEED0, TUNE_SEED0
from execution import Backend
from policies import ParamRange, available_policies, tunable_law, tunable_laws
from policies.space import check_space, params_in_space

# The grids of the former eval/tune.py and eval/line_tune.py: every space must cover them.
FORMER_GRIDS = {
    "pn": {"kv_per_s": (3.0, 8.0), "kw_rad_per_s_px": (0.03, 0.1)},
    "mpn": {"kv_per_s": (3.0, 8.0), "kw_rad_per_s_px": (0.03, 0.1), "lambda_rad_per_px": (0, 3e-3)},
    "gsmpn": {
        "kv_per_s": (3.0, 8.0),
        "kw_rad_per_s_px": (0.03, 0.1),
        "lambda_d": (1e-4, 1e-2),
        "a": (1e-3, 0.1),
    },
    "coordinate": {"speed_mps": (0.15, 0.5), "turn_gain": (2.0, 16.0)},
    "pid": {"speed_mps": (0.15, 0.5), "kp": (2.0, 40.0), "kd": (0.0, 1.0)},
}


def _study(tmp_path: Path, name: str, config: SearchConfig) -> optuna.Study:
    return open_study(tmp_path / f"{name}.journal", name, config)


def _pn_objective(workers: int = 1, kind: str = "local") -> LawObjective:
    return LawObjective(tunable_law("pn"), ("straight",), Backend(kind, workers=workers))


def test_the_five_laws_are_tunable_and_a_law_without_a_space_is_not() -> None:
    assert tunable_laws() == ["coordinate", "gsmpn", "mpn", "pid", "pn"]
    assert tunable_laws("line_trace") == ["coordinate", "pid"]
    assert "holonomic" in available_policies()
    with pytest.raises(ValueError, match="'holonomic' has no search space"):
        tunable_law("holonomic")


@pytest.mark.parametrize("law", sorted(FORMER_GRIDS))
def test_every_search_space_is_valid_and_covers_the_former_grid(law: str) -> None:
    tunable = tunable_law(law)
    check_space(tunable.space, tunable.base)  # fields exist, ends build valid parameters
    assert all(rng.low < rng.high for rng in tunable.space.values())
    assert params_in_space(tunable.space, tunable.base)  # the current preset can be a trial
    for name, (low, high) in FORMER_GRIDS[law].items():
        assert tunable.space[name].low <= low, name
        assert high <= tunable.space[name].high, name


def test_a_space_that_does_not_fit_its_parameters_is_refused() -> None:
    base = tunable_law("pn").base
    with pytest.raises(ValueError, match="not a field of PNParams"):
        check_space({"kp": ParamRange(1.0, 2.0)}, base)
    with pytest.raises(ValueError, match="kv_per_s"):
        check_space({"kv_per_s": ParamRange(0.0, 2.0)}, base)  # kv must be > 0
    with pytest.raises(ValueError, match="must be > 0 for a log range"):
        ParamRange(0.0, 1.0, log=True)
    with pytest.raises(ValueError, match="must be below high"):
        ParamRange(2.0, 1.0)


def test_rungs_take_a_quarter_a_half_then_all_seeds() -> None:
    assert rungs(12) == (3, 6, 12)
    assert rungs(2) == (1, 2)
    assert rungs(1) == (1,)


def test_seed_ranges_are_disjoint() -> None:
    assert max(EVAL_SEEDS) < TUNE_SEED0
    assert TUNE_SEED0 + 1000 <= HOLDOUT_SEED0


def test_a_small_study_finds_a_best_trial_within_the_space(tmp_path: Path) -> None:
    config = SearchConfig(trials=3, seeds=(TUNE_SEED0,), batch=2)
    study = _study(tmp_path, "small", config)
    law = tunable_law("pn")
    base = {k: getattr(law.base, k) for k in law.space}
    assert run_search(study, law.space, config, _pn_objective(), enqueue=base) == 3
    assert len(study.trials) == 3
    assert study.trials[0].params == base  # the current preset runs first
    assert params_in_space(law.space, law.params(study.best_trial.params))
    assert np.isfinite(study.best_value)


def test_the_same_seed_gives_the_same_trials(tmp_path: Path) -> None:
    config = SearchConfig(trials=3, seeds=(TUNE_SEED0,), batch=1, sampler_seed=7)
    runs = []
    for name in ("a", "b"):
        study = _study(tmp_path, name, config)
        run_search(study, tunable_law("pn").space, config, _pn_objective())
        runs.append([(t.params, t.value) for t in study.trials])
    assert runs[0] == runs[1]


def _toy(params: list[dict[str, float]], seeds: list[int]) -> list[dict[str, np.ndarray]]:
    """Score -(100 (x - 0.5))^2 on every seed: a trial far from 0.5 trails from its first rung."""
    return [{"score": np.full((1, len(seeds)), -((100 * (p["x"] - 0.5)) ** 2))} for p in params]


def test_a_trailing_trial_is_pruned_on_a_partial_seed_set(tmp_path: Path) -> None:
    config = SearchConfig(trials=12, seeds=tuple(range(4)), batch=1, startup_trials=2)
    study = _study(tmp_path, "toy", config)
    run_search(study, {"x": ParamRange(0.0, 1.0)}, config, _toy, enqueue={"x": 0.5})
    pruned = study.get_trials(states=(TrialState.PRUNED,))
    assert pruned, "no trial was pruned"
    assert all(t.user_attrs["seeds"] < 4 for t in pruned)  # stopped before the last rung
    assert study.best_trial.params == {"x": 0.5}


def test_choose_replaces_the_preset_only_on_evidence() -> None:
    rng = np.random.default_rng(0)
    noise = rng.normal(0.0, 1.0, 40)
    own = rng.normal(0.0, 1.0, 40)  # the trial's episodes differ from the preset's ...
    own -= own.mean()  # ... but not on average
    current = Candidate("pn:tuned", {"x": 0.0})
    trial = Candidate("trial 1", {"x": 1.0}, trial=1)

    def rows(shift: float, trial_turn: float) -> list[dict]:
        same = {"turn_accel_rms_rad_s2": np.full(40, 1.0), "failed": np.zeros(40)}
        episodes = [
            {
                "score": 100 + noise + own + shift,
                **same,
                "turn_accel_rms_rad_s2": np.full(40, trial_turn),
            },
            {"score": 100 + noise, **same},
        ]
        return choose([trial, current], episodes)

    better = rows(5.0, trial_turn=2.0)  # clearly better, though less smooth
    assert better[0]["chosen"]
    assert better[0]["diff_ci_low"] > 0
    rougher = rows(0.0, trial_turn=2.0)  # as good, less smooth: the preset stays
    assert rougher[0]["diff_ci_low"] < 0 < rougher[0]["diff_ci_high"]
    assert rougher[1]["chosen"]
    assert not rougher[0]["chosen"]
    smoother = rows(0.0, trial_turn=0.5)  # as good, smoother: replaced
    assert smoother[0]["chosen"]
    assert smoother[1]["within_1se"]


def _two(trial_score: np.ndarray, preset_score: np.ndarray) -> list[dict]:
    """The held-out rows of a rougher trial against the preset, on the same episodes."""
    n = len(preset_score)
    episodes = [
        {"score": trial_score, "turn_accel_rms_rad_s2": np.full(n, 2.0), "failed": np.zeros(n)},
        {"score": preset_score, "turn_accel_rms_rad_s2": np.full(n, 1.0), "failed": np.zeros(n)},
    ]
    return choose([Candidate("trial 1", {"x": 1.0}, trial=1), Candidate("pn:tuned", {})], episodes)


def test_a_ci_above_zero_is_not_enough_without_the_permutation_test() -> None:
    """Five of 40 paired episodes 10 better, the rest alike: the bootstrap CI lies above 0, but
    the sign-flip test of those five gives p = 2/32; by the evaluation's rule that is a tie, and
    a rougher trial does not replace the preset on it."""
    preset = np.random.default_rng(1).normal(100.0, 1.0, 40)
    jumps = np.zeros(40)
    jumps[[3, 11, 19, 27, 35]] = 10.0
    rows = _two(preset + jumps, preset)
    assert rows[0]["diff_ci_low"] > 0
    assert 0.05 <= rows[0]["diff_perm_p"] < 0.08
    assert rows[0]["within_1se"]  # the top scorer: only the rule keeps it out
    assert rows[1]["chosen"]
    assert verdict(rows) == "keep pn:tuned: no trial is better on the held-out seeds by the rule"


def test_a_trial_better_by_the_rule_replaces_the_preset_and_the_verdict_says_so() -> None:
    rng = np.random.default_rng(2)
    preset = rng.normal(100.0, 1.0, 40)
    rows = _two(preset + 2.0 + rng.normal(0.0, 0.5, 40), preset)
    assert rows[0]["chosen"]
    assert rows[0]["diff_perm_p"] < 0.05 < rows[1]["diff_perm_p"]
    said = verdict(rows)
    assert said.startswith("replace pn:tuned by trial 1: better than the current preset (its")
    assert "95 % CI is above 0, the permutation test's p < 0.05 with Holm's correction" in said
    assert said.endswith(f"p {rows[0]['diff_perm_p']:.2g} (Holm {rows[0]['diff_holm_p']:.2g})")


def _held(scores: list[np.ndarray], turns: list[float]) -> list[dict]:
    """The held-out rows of trials 1.. and the preset (last), each turning at a constant rate
    with a little noise of its own."""
    rng = np.random.default_rng(7)
    n = len(scores[0])
    episodes = [
        {
            "score": score,
            "turn_accel_rms_rad_s2": turn + rng.normal(0.0, 0.01, n),
            "failed": np.zeros(n),
        }
        for score, turn in zip(scores, turns, strict=True)
    ]
    labels = [
        Candidate(f"trial {k + 1}", {"x": float(k)}, trial=k + 1) for k in range(len(scores) - 1)
    ]
    return choose([*labels, Candidate("pn:tuned", {"x": -1.0})], episodes)


def test_a_better_trial_is_not_passed_over_for_a_smoother_one_without_evidence() -> None:
    # trial 1 is clearly better than the preset; trial 2 is as good as trial 1 within one SE,
    # smoother than it but rougher than the preset, and not better than the preset by the rule:
    # the smoothest "as good" candidate used to be picked first, failed the test, and the
    # preset stayed with "no trial is better"
    rng = np.random.default_rng(3)
    preset = rng.normal(180.0, 1.0, 60)
    first = preset + 10.0 + rng.normal(0.0, 0.5, 60)
    second = preset + 6.0 + 40.0 * np.tile([1.0, -1.0], 30)  # +6 on average, +-40 an episode
    rows = _held([first, second, preset], turns=[2.0, 1.5, 1.0])
    assert rows[1]["within_1se"]
    assert rows[1]["diff_perm_p"] >= 0.05
    assert rows[0]["chosen"]
    assert verdict(rows).startswith("replace pn:tuned by trial 1: better")


def test_the_trials_evidence_is_adjusted_over_the_trials() -> None:
    # one of three trials passes alone (p < 0.05), not after Holm's correction over three:
    # 40 episodes, 27 of them +1 better and 13 -1 worse (p about 0.04), the other two level
    preset = np.random.default_rng(4).normal(100.0, 1.0, 40)
    steps = np.where(np.arange(40) < 27, 1.0, -1.0)
    level = 0.5 * np.tile([1.0, -1.0], 20)
    rows = _held([preset + steps, preset + level, preset - level, preset], turns=[1.0] * 4)
    assert rows[0]["diff_perm_p"] < 0.05
    assert rows[0]["diff_holm_p"] >= 0.05
    assert rows[-1]["chosen"]


def test_a_trivial_gain_does_not_replace_the_preset() -> None:
    # paired, nearly identical rollouts: +0.1 % is significant, and less than MIN_GAIN
    preset = np.random.default_rng(5).normal(180.0, 5.0, 60)
    rows = _held([preset + 0.18, preset], turns=[1.0, 1.0])
    assert rows[0]["diff_perm_p"] < 0.05
    assert rows[0]["diff_vs_current"] < MIN_GAIN * rows[1]["holdout_mean"]
    assert rows[1]["chosen"]


def test_smoother_by_its_mean_alone_is_not_enough() -> None:
    # the same score; the trial's turn 0.06 lower on average, +-0.3 an episode: no evidence
    preset = np.random.default_rng(6).normal(100.0, 1.0, 40)
    turns = 1.0 + 0.3 * np.tile([1.0, -1.0], 20)
    rougher_or_smoother = 0.3 * np.tile([1.0, 1.0, -1.0, -1.0], 10)
    zeros = np.zeros(40)
    episodes = [
        {
            "score": preset,
            "turn_accel_rms_rad_s2": turns - 0.06 + rougher_or_smoother,
            "failed": zeros,
        },
        {"score": preset, "turn_accel_rms_rad_s2": turns, "failed": zeros},
    ]
    rows = choose([Candidate("trial 1", {"x": 1.0}, trial=1), Candidate("pn:tuned", {})], episodes)
    assert rows[0]["turn_accel_rms_rad_s2"] < rows[1]["turn_accel_rms_rad_s2"]
    assert rows[0]["smoother_perm_p"] >= 0.05
    assert rows[1]["chosen"]


def test_a_candidate_that_failed_more_often_than_the_top_is_not_as_good() -> None:
    top = {"score": np.full(20, 100.0), "turn_accel_rms_rad_s2": np.full(20, 2.0)}
    crash = np.full(20, 100.5)
    crash[0] = 60.0  # one failed episode: its mean is close, its standard error wide
    rough = {"score": crash, "turn_accel_rms_rad_s2": np.full(20, 1.0)}
    failed = np.zeros(20)
    rows = choose(
        [Candidate("trial 1", {"x": 1.0}, trial=1), Candidate("preset", {"x": 0.0})],
        [{**rough, "failed": np.eye(20)[0]}, {**top, "failed": failed}],
    )
    assert not rows[0]["within_1se"]
    assert rows[1]["chosen"]


def _cli(tmp_path: Path, *extra: str) -> list[str]:
    return [
        "pn",
        "--scenarios",
        "straight",
        "--seeds",
        "2",
        "--holdout-seeds",
        "2",
        "--out",
        str(tmp_path / "out"),
        *extra,
    ]


@pytest.mark.slow
def test_rerunning_the_command_resumes_the_study_and_runs_only_the_rest(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    copy = tmp_path / "preset.txt"
    assert main(_cli(tmp_path, "--trials", "2", "--write-preset", str(copy))) == 0
    first = json.loads((tmp_path / "out" / "result.json").read_text())
    assert first["ran_now"] == 2
    assert copy.read_text() == (tmp_path / "out" / "preset.txt").read_text()
    assert main(_cli(tmp_path, "--trials", "3")) == 0
    result = json.loads((tmp_path / "out" / "result.json").read_text())
    assert result["ran_now"] == 1
    assert sum(result["trials"].values()) == 3
    assert main(_cli(tmp_path, "--trials", "3")) == 0  # nothing left to run
    assert json.loads((tmp_path / "out" / "result.json").read_text())["ran_now"] == 0
    rows = result["holdout"]
    assert rows[-1]["label"] == "pn:tuned"
    assert sum(r["chosen"] for r in rows) == 1
    assert all(r["ci_low"] <= r["holdout_mean"] <= r["ci_high"] for r in rows)
    preset = (tmp_path / "out" / "preset.txt").read_text()
    assert "PNParams(" in preset
    assert "follow-tune pn" in preset
    assert "| pn:tuned |" in capsys.readouterr().out
    # Other settings on the same study are refused rather than mixed in.
    assert main(_cli(tmp_path, "--trials", "3", "--seeds", "3")) == 2


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["holonomic"], "has no search space"),
        (["nolaw"], "is not a registered law"),
        (["pn", "--trials", "0"], "argument --trials: 0 is out of range"),
        (["pn", "--storage", "{tmp}/missing/x.journal"], "does not exist"),
        (["pn", "--storage", "{tmp}"], "a folder"),
        (["pn", "--storage", "nosuchdb://x"], "cannot open the storage"),
        (["pn", "--task", "line_trace"], "is a law of the person_follow task"),
        (["pid", "--scenarios", "curve"], "unknown line_trace variant 'curve'"),
        (["pid", "--holdout-scenarios", "gaps,moon"], "--holdout-scenarios: unknown"),
        (["pn", "--address", "auto"], "--address is for --backend ray"),
        (["pn", "--seeds", "1001"], "at most 1000"),
    ],
)
def test_bad_arguments_give_one_line_and_exit_2_writing_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], message: str
) -> None:
    out = tmp_path / "out"
    argv = [a.replace("{tmp}", str(tmp_path)) for a in args] + ["--out", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert err.startswith("follow-tune: error: ")
    assert message in err
    assert not out.exists()


@pytest.mark.slow
def test_the_ray_backend_gives_the_same_trials_as_local(tmp_path: Path, local_ray: object) -> None:
    config = SearchConfig(trials=2, seeds=(TUNE_SEED0,), batch=2)
    found = []
    for kind in ("local", "ray"):
        study = _study(tmp_path, kind, config)
        run_search(study, tunable_law("pn").space, config, _pn_objective(2, kind))
        found.append([(t.params, t.value, t.state) for t in study.trials])
    assert found[0] == found[1]
