"""eval/stats.py: bootstrap means and paired comparisons."""

import numpy as np
import pandas as pd
import pytest

from eval.stats import PairedTest, compare, pairing_notes, summarize


def table(values: dict[str, list[float]], metric: str = "mean_offset_px") -> pd.DataFrame:
    rows = [
        {"policy": p, "scenario": "straight", "seed": s, metric: v}
        for p, vs in values.items()
        for s, v in enumerate(vs)
    ]
    return pd.DataFrame(rows)


def test_summary_mean_and_ci_bracket_the_sample_mean() -> None:
    rng = np.random.default_rng(1)
    values = list(rng.normal(20.0, 3.0, size=20))
    row = summarize(table({"pn": values})).iloc[0]
    assert row["episodes"] == 20
    assert row["mean_offset_px"] == pytest.approx(np.mean(values))
    assert row["mean_offset_px_ci_low"] < row["mean_offset_px"] < row["mean_offset_px_ci_high"]
    # 95 % CI of a mean of 20 draws with sd 3: roughly +- 2 * 3 / sqrt(20) = +- 1.3
    assert 0.5 < row["mean_offset_px_ci_high"] - row["mean_offset_px_ci_low"] < 4.0


def test_summary_is_reproducible_for_a_seed() -> None:
    t = table({"pn": [1.0, 2.0, 4.0, 8.0, 3.0]})
    pd.testing.assert_frame_equal(summarize(t, seed=3), summarize(t, seed=3))


def test_identical_values_give_a_zero_width_interval() -> None:
    row = summarize(table({"pn": [100.0] * 5}, "in_frame_rate_pct")).iloc[0]
    assert row["in_frame_rate_pct_ci_low"] == row["in_frame_rate_pct_ci_high"] == 100.0


def test_one_episode_has_no_interval() -> None:
    row = summarize(table({"pn": [3.0]})).iloc[0]
    assert row["mean_offset_px"] == 3.0
    assert np.isnan(row["mean_offset_px_ci_low"])


def test_nan_episodes_are_left_out_of_a_metric() -> None:
    row = summarize(table({"pn": [1.0, np.nan, 3.0]}, "reacquire_time_s")).iloc[0]
    assert row["reacquire_time_s"] == pytest.approx(2.0)


def test_summary_keeps_the_order_policies_first_appear_in() -> None:
    t = table({"mpn": [1.0, 2.0], "pn": [3.0, 4.0]})
    assert list(summarize(t)["policy"]) == ["mpn", "pn"]


def test_paired_comparison_on_same_seeds() -> None:
    # B is A + 2 on every seed, plus a little noise: A - B is about -2 and clearly significant.
    a = [10.0, 12.0, 9.0, 15.0, 11.0, 13.0, 10.5, 14.0, 9.5, 12.5]
    b = [x + 2.0 + 0.1 * k for k, x in enumerate(a)]
    [row] = compare(table({"a": a, "b": b})).to_dict("records")
    assert (row["policy_a"], row["policy_b"], row["n"]) == ("a", "b", 10)
    assert row["mean_diff"] == pytest.approx(np.mean(np.subtract(a, b)))
    assert row["diff_ci_low"] < row["mean_diff"] < row["diff_ci_high"] < 0
    assert row["wilcoxon_p"] < 0.01


def test_paired_comparison_of_equal_policies_has_no_p_value() -> None:
    [row] = compare(table({"a": [1.0, 2.0, 3.0], "b": [1.0, 2.0, 3.0]})).to_dict("records")
    assert row["mean_diff"] == 0.0
    assert np.isnan(row["wilcoxon_p"])


def test_an_interval_does_not_depend_on_the_order_of_episodes_or_other_cells() -> None:
    rng = np.random.default_rng(7)
    t = table({"pn": list(rng.normal(20, 3, 12)), "mpn": list(rng.normal(21, 3, 12))})
    shuffled = t.sample(frac=1.0, random_state=3)  # e.g. log files read in another order
    alone = t[t["policy"] == "pn"]  # the same cell without its neighbour
    key = ["policy", "scenario"]
    a = summarize(t).sort_values(key, ignore_index=True)
    b = summarize(shuffled).sort_values(key, ignore_index=True)
    pd.testing.assert_frame_equal(a, b)
    pd.testing.assert_frame_equal(summarize(alone), a[a["policy"] == "pn"].reset_index(drop=True))


def test_a_comparison_does_not_depend_on_the_order_of_episodes() -> None:
    rng = np.random.default_rng(8)
    t = table({"a": list(rng.normal(10, 2, 12)), "b": list(rng.normal(11, 2, 12))})
    seeds_descending = t.sort_values(["policy", "seed"], ascending=[True, False])
    pd.testing.assert_frame_equal(compare(t), compare(seeds_descending))


@pytest.mark.parametrize("budget", [2**18, 997, 1])
def test_resampling_in_batches_gives_the_intervals_of_all_at_once(
    budget: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    import eval.stats

    rng = np.random.default_rng(7)
    n = 300 if budget > 1 else 40  # one resample a call is slow: fewer episodes
    # 2**18 values is 873 resamples of 300 a call, 997 is 3, 1 is one; a rare event's metric
    # (mostly zeros) beside a smooth one.
    values = {p: list(rng.normal(mu, 2.0, size=n)) for p, mu in (("pn", 20.0), ("mpn", 20.3))}
    rare = {p: [float(k == 5) for k in range(n)] for p in values}
    t = table(values).assign(collision_rate_pct=table(rare, "c")["c"])
    monkeypatch.setattr(eval.stats, "BOOTSTRAP_BATCH_VALUES", budget)
    assert eval.stats._batch(n) < eval.stats.N_RESAMPLES  # really in batches
    batched = (summarize(t), compare(t))
    monkeypatch.setattr(eval.stats, "BOOTSTRAP_BATCH_VALUES", None)
    at_once = (summarize(t), compare(t))
    for got, expected in zip(batched, at_once, strict=True):
        pd.testing.assert_frame_equal(got, expected)


@pytest.mark.parametrize("n", [2, 5, 13, 30])
def test_the_sign_flip_test_gives_scipys_permutation_p(n: int) -> None:
    """Exact (all 2**n flips) up to 13 pairs, as scipy's permutation_test with
    permutation_type="samples" on one sample is; drawn flips above that, within their noise."""
    from scipy import stats

    import eval.stats

    rng = np.random.default_rng(n)
    diff = np.where(rng.random(n) < 0.3, rng.normal(2.0, 3.0, n), 0.0)
    diff[0] = 1.5
    got = eval.stats.paired_test(diff, 0, "x").p
    want = stats.permutation_test(
        (diff,), np.mean, permutation_type="samples", n_resamples=9999, random_state=1
    ).pvalue
    if 2**n <= eval.stats.N_SIGN_FLIPS:
        assert got == pytest.approx(want, rel=1e-12)
    else:
        assert abs(got - want) < 0.02
    assert eval.stats.paired_test(diff, 0, "x") == eval.stats.paired_test(diff, 0, "x")


def test_a_difference_is_significant_only_if_the_ci_and_the_permutation_test_say_so() -> None:
    from eval.report import comparison_markdown

    # +1 on each of 5 seeds: the CI is the point [1, 1], but of the 32 sign flips two are as
    # far from 0 (all + and all -): p = 0.0625, not significant; on 6 seeds p = 0.031 is.
    for n, expected in ((5, 0), (6, 1)):
        [row] = compare(table({"a": [2.0] * n, "b": [1.0] * n})).to_dict("records")
        assert (row["diff_ci_low"], row["diff_ci_high"]) == (1.0, 1.0)
        assert row["perm_p"] == pytest.approx(2 / 2**n)
        test = PairedTest(row["mean_diff"], row["diff_ci_low"], row["diff_ci_high"], row["perm_p"])
        assert test.direction == expected
        shown = comparison_markdown(compare(table({"a": [2.0] * n, "b": [1.0] * n})))
        assert ("1.0 [1.0, 1.0]* p=" in shown) == bool(expected)  # starred when significant
    [row] = compare(table({"a": [1.0, 2.0, 3.0], "b": [1.0, 2.0, 3.0]})).to_dict("records")
    assert row["perm_p"] == 1.0  # identical on every seed


def test_rates_of_episodes_get_a_wilson_interval_that_does_not_collapse() -> None:
    """No collision in 20 episodes is not a rate known to be 0: [0, 16.1] %, not [0, 0]."""
    t = table({"pn": [0.0] * 20, "mpn": [100.0] * 19 + [0.0]}, "collision_rate_pct")
    rows = summarize(t).set_index("policy")
    assert rows.loc["pn", "collision_rate_pct_ci_low"] == 0.0
    assert rows.loc["pn", "collision_rate_pct_ci_high"] == pytest.approx(16.11, abs=0.01)
    assert rows.loc["mpn", "collision_rate_pct_ci_low"] == pytest.approx(76.39, abs=0.01)
    # decided by the metric's registration, not the data: a 0/100 column of a metric that is
    # no rate of episodes keeps its bootstrap interval
    t = table({"pn": [0.0] * 20}, "in_frame_rate_pct")
    assert summarize(t).iloc[0]["in_frame_rate_pct_ci_high"] == 0.0


def test_the_summary_counts_each_metrics_episodes_and_the_report_shows_them() -> None:
    from eval.report import summary_markdown

    reacquire = [1.0, np.nan, 3.0] * 4  # a value on 8 of 12 episodes
    t = table({"pn": reacquire, "mpn": [2.0] * 3}, "reacquire_time_s")
    summary = summarize(t)
    assert summary["reacquire_time_s_n"].tolist() == [8, 3]
    text = summary_markdown(summary, extras=True)
    pn, mpn = (line for line in text.splitlines() if line.startswith(("| pn", "| mpn")))
    assert pn.split("|")[4].strip().endswith("]† (n=8)")  # 8 values (< 10: marked) of 12
    assert mpn.split("|")[4].strip() == "2.000 [2.000, 2.000]†"  # all 3, but fewer than 10
    assert text.endswith("(about 80 % at 5).")  # the footnote says what the mark means


def test_pairs_on_different_seeds_are_noted() -> None:
    from eval.report import markdown_report

    t = pd.concat([table({"a": [1.0] * 6, "b": [2.0] * 4}), table({"c": [1.0]}).assign(seed=9)])
    pairs = compare(t).set_index("policy_b")
    assert pairs.loc["b", ["n", "seeds_a", "seeds_b", "seeds_both"]].tolist() == [4, 6, 4, 4]
    assert pairs.loc["c", "n"].tolist() == [0, 0]  # a - c and b - c kept, nothing paired
    assert pairing_notes(compare(t)) == [
        "scenario straight: a ran 6 seeds and b 4; compared on the 4 both ran",
        "scenario straight: a ran 6 seeds and c 1; they share none: not compared",
        "scenario straight: b ran 4 seeds and c 1; they share none: not compared",
    ]
    report = markdown_report(summarize(t), compare(t))
    assert "**Different seeds.**" in report
    assert "- scenario straight: a ran 6 seeds and c 1; they share none: not compared" in report


def test_holm_adjusts_each_metrics_comparisons_over_every_scenario_and_pair() -> None:
    from eval.stats import holm, with_holm

    rng = np.random.default_rng(3)
    rows = [
        {"policy": p, "scenario": s, "seed": k, "x": rng.normal(shift), "y": rng.normal()}
        for s in ("straight", "curve")
        for p, shift in (("a", 0.0), ("b", 0.8), ("c", 0.3))
        for k in range(12)
    ]
    got = compare(pd.DataFrame(rows), metrics=["x", "y"])
    assert list(got.columns).index("holm_p") == list(got.columns).index("perm_p") + 1
    for metric in ("x", "y"):
        rows_m = got[got["metric"] == metric]
        assert len(rows_m) == 6  # 3 pairs x 2 scenarios: the family of one metric
        np.testing.assert_array_equal(rows_m["holm_p"], holm(rows_m["perm_p"].to_numpy()))
    # per line p < 0.05 on the shift, and the adjustment only ever raises a p
    assert (got["holm_p"] >= got["perm_p"]).all()
    assert (got["holm_p"] > got["perm_p"]).any()
    # adjusted again over the whole table, a table's holm_p does not depend on its parts
    parts = [
        compare(pd.DataFrame(rows).query("scenario == @s"), metrics=["x", "y"])
        for s in ("straight", "curve")
    ]
    joined = with_holm(pd.concat(parts, ignore_index=True))
    pd.testing.assert_frame_equal(joined, got)
    assert not pd.concat(parts, ignore_index=True)["holm_p"].equals(got["holm_p"])


def test_the_report_says_how_many_starred_differences_stand_under_holm() -> None:
    from eval.report import holm_note, markdown_report
    from eval.stats import summarize

    # +1 on each of 6 seeds: p = 2/64 = 0.031 per line, starred; two scenarios make a family
    # of two, and Holm's 0.0625 does not stand. One more seed (p = 0.016, Holm 0.031) does.
    for n, stand in ((6, 0), (7, 2)):
        rows = [
            {"policy": p, "scenario": s, "seed": k, "in_frame_rate_pct": v}
            for s in ("straight", "curve")
            for p, v in (("a", 2.0), ("b", 1.0))
            for k in range(n)
        ]
        frame = pd.DataFrame(rows)
        comparisons = compare(frame, metrics=["in_frame_rate_pct"])
        note = holm_note(comparisons)
        assert f"per metric: InFrameRate (%) {stand} of 2." in note
        # on 6 seeds no p is below 2/64, and a family of two needs one below 0.025: the note
        # says that none can stand, so that "0 of 2" is not read as a verdict on the data
        floor = "with 2 comparisons a line needs p < 0.025, and the permutation test's p is at "
        assert (f"InFrameRate (%): none can stand, whatever the data: {floor}" in note) == (n == 6)
        report = markdown_report(summarize(frame, metrics=["in_frame_rate_pct"]), comparisons)
        assert note in report
    from eval.stats import paired_test, smallest_p

    # the floor the note uses is the test's: exact up to 13 pairs, drawn (9,999 flips) beyond
    assert paired_test(np.ones(6), 0, "x").p == smallest_p(6) == 2 / 64
    assert paired_test(np.ones(20), 0, "x").p == smallest_p(20) == 2 / 10_000
    assert holm_note(comparisons.drop(columns="holm_p")) == ""  # a table written before
    assert holm_note(compare(table({"a": [1.0] * 6, "b": [1.0] * 6}))) == ""  # nothing starred
