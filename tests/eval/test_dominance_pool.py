"""follow-eval dominance RUN RUN... --out DIR: runs on disjoint seeds pooled into one table."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from eval.cli import main
from eval.dominance import CRITERIA, dominance

METRICS = [c.metric for c in CRITERIA]
POLICIES = ("ppo", "pn:tuned", "gsmpn:tuned")
META = {
    "task": "person_follow",
    "config": "thesis",
    "ideal_baseline": False,
    "policies": {"ppo": "PPOPolicy(name='ppo')", "pn:tuned": "PNParams(kv=5)"},
    "model_sha256": {"ppo": "a0" * 32},  # a learned policy's files (laws have none)
    "code": {"sources_sha256": "c0de" * 16, "git": "1234567890ab" * 3 + "cdef", "git_dirty": False},
}


def _run(folder: Path, first_seed: int, n: int, *, meta: dict | None = None) -> Path:
    """A run folder as follow-eval run leaves it (the parts dominance reads): every policy on
    two scenarios, seeds first_seed..first_seed+n-1, with noisy metrics."""
    rng = np.random.default_rng(first_seed)
    rows = []
    for policy in POLICIES:
        for scenario in ("straight", "crowd"):
            for seed in range(first_seed, first_seed + n):
                row = {"policy": policy, "scenario": scenario, "seed": seed}
                row.update({m: float(rng.normal(50.0, 5.0)) for m in METRICS})
                rows.append(row)
    folder.mkdir()
    pd.DataFrame(rows).to_csv(folder / "episodes.csv", index=False)
    (folder / "meta.json").write_text(json.dumps(META if meta is None else meta))
    return folder


def _listing(*folders: Path) -> dict[Path, list[str]]:
    return {f: sorted(p.name for p in f.iterdir()) for f in folders}


def test_runs_on_disjoint_seeds_are_judged_as_one_table(tmp_path: Path, capsys) -> None:
    a, b = _run(tmp_path / "a", 0, 6), _run(tmp_path / "b", 100, 9)
    before = _listing(a, b)
    out = tmp_path / "pooled"
    assert main(["dominance", str(a), str(b), "--learner", "ppo", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "Pooled from 2 runs" in printed
    assert "15 episodes per policy and scenario" in printed
    both = pd.concat([pd.read_csv(a / "episodes.csv"), pd.read_csv(b / "episodes.csv")])
    expected = dominance(both.reset_index(drop=True), "ppo", ["pn:tuned", "gsmpn:tuned"])
    written = pd.read_csv(out / "dominance-ppo.csv")
    assert written["n"].tolist() == [15] * len(written)  # every line paired over both runs
    assert np.allclose(written["diff"], expected["diff"])
    assert written["verdict"].tolist() == expected["verdict"].tolist()
    pooled = pd.read_csv(out / "episodes.csv")
    assert len(pooled) == len(both)
    assert sorted(p.name for p in out.iterdir()) == [
        "dominance-ppo-finished.csv",
        "dominance-ppo.csv",
        "dominance-ppo.md",
        "episodes.csv",
    ]
    assert (out / "dominance-ppo.md").read_text().startswith("Pooled from 2 runs")
    assert _listing(a, b) == before  # the runs themselves are left as they were


def test_one_run_may_write_into_a_new_folder_too(tmp_path: Path) -> None:
    a = _run(tmp_path / "a", 0, 5)
    out = tmp_path / "judged"
    assert main(["dominance", str(a), "--learner", "ppo", "--out", str(out)]) == 0
    assert (out / "dominance-ppo.md").is_file()
    assert _listing(a) == {a: ["episodes.csv", "meta.json"]}


def _changed(key: str, value: object) -> dict:
    meta = json.loads(json.dumps(META))
    meta[key] = value
    return meta


@pytest.mark.parametrize(
    ("meta", "message"),
    [
        (_changed("config", {"perception": {"association": "tracker"}}), "its config is"),
        (_changed("ideal_baseline", True), "its ideal_baseline is True"),
        (
            _changed("policies", {"pn:tuned": "PNParams(kv=6)"}),
            "pn:tuned is PNParams(kv=6) there and PNParams(kv=5) in",
        ),
    ],
)
def test_runs_made_differently_are_not_pooled(
    tmp_path: Path, capsys, meta: dict, message: str
) -> None:
    a, b = _run(tmp_path / "a", 0, 4), _run(tmp_path / "b", 10, 4, meta=meta)
    out = tmp_path / "pooled"
    assert main(["dominance", str(a), str(b), "--learner", "ppo", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert f"error: {b}: " in err
    assert message in err
    assert not out.exists()


def test_an_episode_in_two_runs_is_refused_naming_both(tmp_path: Path, capsys) -> None:
    a, b = _run(tmp_path / "a", 0, 4), _run(tmp_path / "b", 3, 4)  # seed 3 in both
    out = tmp_path / "pooled"
    assert main(["dominance", str(a), str(b), "--learner", "ppo", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"seed 3 of straight for ppo is in {a} and {b}: pool runs of disjoint seeds" in err
    assert not out.exists()


def test_every_run_pooled_must_hold_each_policy_judged(tmp_path: Path, capsys) -> None:
    a, b = _run(tmp_path / "a", 0, 4), _run(tmp_path / "b", 10, 4)
    table = pd.read_csv(b / "episodes.csv")
    table = table[(table["policy"] != "gsmpn:tuned") | (table["scenario"] != "crowd")]
    table.to_csv(b / "episodes.csv", index=False)
    out = tmp_path / "pooled"
    assert main(["dominance", str(a), str(b), "--learner", "ppo", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{b}: holds no episode of gsmpn:tuned on crowd: every run pooled must hold" in err
    assert not out.exists()
    # a policy that is not judged may be missing: here gsmpn:tuned is left out of the laws
    argv = [str(a), str(b), "--learner", "ppo", "--laws", "pn:tuned", "--out", str(out)]
    assert main(["dominance", *argv]) == 0
    assert set(pd.read_csv(out / "dominance-ppo.csv")["n"]) == {8}
    pooled = pd.read_csv(out / "episodes.csv")
    assert sorted(set(pooled["run"])) == sorted([str(a), str(b)])  # where each episode came from


def test_runs_of_different_scenarios_are_refused(tmp_path: Path, capsys) -> None:
    a, b = _run(tmp_path / "a", 0, 4), _run(tmp_path / "b", 10, 4)
    table = pd.read_csv(b / "episodes.csv")
    table[table["scenario"] != "crowd"].to_csv(b / "episodes.csv", index=False)
    out = tmp_path / "pooled"
    assert main(["dominance", str(a), str(b), "--learner", "ppo", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{b}: holds the scenarios ['straight'] and {a} ['crowd', 'straight']" in err
    assert not out.exists()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["{a}", "{b}"], "2 runs are pooled: give --out"),
        (["{a}", "{a}/", "--out", "{out}"], "given twice"),
        (["{a}", "{bare}", "--out", "{out}"], "meta.json: no such file; pooling reads it"),
        (["{a}", "{b}", "--out", "{a}"], "already exists and is not an empty folder"),
    ],
)
def test_a_bad_pool_writes_nothing(tmp_path: Path, capsys, args: list, message: str) -> None:
    a, b = _run(tmp_path / "a", 0, 4), _run(tmp_path / "b", 10, 4)
    bare = _run(tmp_path / "bare", 20, 4)
    (bare / "meta.json").unlink()
    before = _listing(a, b, bare)
    names = {"a": a, "b": b, "bare": bare, "out": tmp_path / "pooled"}
    argv = [arg.format(**names) for arg in args]
    assert main(["dominance", *argv, "--learner", "ppo"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert message in err
    assert _listing(a, b, bare) == before
    assert not (tmp_path / "pooled").exists()


def test_a_corrupt_meta_is_named(tmp_path: Path, capsys) -> None:
    a, b = _run(tmp_path / "a", 0, 4), _run(tmp_path / "b", 10, 4)
    (b / "meta.json").write_text("{not json")
    assert (
        main(["dominance", str(a), str(b), "--learner", "ppo", "--out", str(tmp_path / "o")]) == 2
    )
    assert f"{b / 'meta.json'}: not a run's meta.json" in capsys.readouterr().err


def test_an_episode_twice_in_one_run_is_refused_by_its_line(tmp_path: Path, capsys) -> None:
    """A repeated (policy, scenario, seed) would be paired with every copy of the other side."""
    a = _run(tmp_path / "a", 0, 4)
    table = pd.read_csv(a / "episodes.csv")
    pd.concat([table, table.iloc[[5]]]).to_csv(a / "episodes.csv", index=False)
    message = f"{a / 'episodes.csv'}: line {len(table) + 2}: seed 1 of crowd for ppo is there twice"
    assert main(["dominance", str(a), "--learner", "ppo"]) == 2
    assert message in capsys.readouterr().err
    assert _listing(a) == {a: ["episodes.csv", "meta.json"]}
    # pooled, the run's own repeat is named the same way, not as an episode of two runs
    b, out = _run(tmp_path / "b", 10, 4), tmp_path / "pooled"
    assert main(["dominance", str(b), str(a), "--learner", "ppo", "--out", str(out)]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def _with_digest(digest: str | None, model: str = "PPOPolicy(name='ppo')") -> dict:
    meta = _changed("policies", {**META["policies"], "ppo": model})
    meta.pop("model_sha256")
    if digest is not None:
        meta["model_sha256"] = {"ppo": digest}
    return meta


@pytest.mark.parametrize(
    ("mine", "theirs", "pooled"),
    [
        ((None, "A"), (None, "A"), True),  # runs written before the digests: by the repr
        (("aa" * 32, "A"), (None, "A"), True),  # one digest: the repr is what both have
        (("aa" * 32, "A"), (None, "B"), False),
        (("aa" * 32, "A"), ("aa" * 32, "B"), True),  # the same files, loaded from elsewhere
        (("aa" * 32, "A"), ("bb" * 32, "A"), False),  # the same path, other files
    ],
)
def test_a_label_pools_by_its_models_digest_where_both_runs_record_one(
    tmp_path: Path, capsys, mine: tuple, theirs: tuple, pooled: bool
) -> None:
    a = _run(tmp_path / "a", 0, 4, meta=_with_digest(mine[0], mine[1]))
    b = _run(tmp_path / "b", 10, 4, meta=_with_digest(theirs[0], theirs[1]))
    out = tmp_path / "pooled"
    code = main(["dominance", str(a), str(b), "--learner", "ppo", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == (0 if pooled else 2), err
    assert out.exists() == pooled
    if not pooled:
        assert err.count("\n") == 1
        assert f"error: {b}: " in err
        assert "pool runs of the same controllers" in err
        if mine[0] and theirs[0]:
            assert f"the model under ppo is not the one in {a} (SHA-256 of its files bbbb" in err


def test_two_runs_of_one_agent_path_holding_two_models_are_not_pooled(
    tmp_path: Path, capsys, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``--policies agent`` in two folders: the same relative path, the same repr, and two
    models (here their config.yaml differs by a comment)."""
    import hashlib
    import shutil

    shipped = Path(__file__).parents[2] / "policies" / "agents" / "ppo"
    runs = []
    for first_seed, where in ((0, tmp_path / "a"), (10, tmp_path / "b")):
        shutil.copytree(shipped, where / "agent")
        if first_seed:
            with (where / "agent" / "config.yaml").open("a") as f:
                f.write("# retrained\n")
        monkeypatch.chdir(where)
        grid = ["--policies", "agent,pn", "--scenarios", "straight", "--episodes", "2"]
        argv = ["run", *grid, "--seed", str(first_seed), "--no-logs", "--out", "run"]
        assert main([*argv, "--workers", "1"]) == 0
        runs.append(where / "run")
    capsys.readouterr()
    metas = [json.loads((run / "meta.json").read_text()) for run in runs]
    assert metas[0]["policies"]["agent"] == metas[1]["policies"]["agent"]  # the repr: a path
    files = ("model.zip", "vecnormalize.pkl", "config.yaml")
    for meta, where in zip(metas, (tmp_path / "a", tmp_path / "b"), strict=True):
        expected = hashlib.sha256()
        for role, name in zip(("model", "normalization", "config"), files, strict=True):
            data = (where / "agent" / name).read_bytes()
            expected.update(role.encode() + b"\0%d\0" % len(data) + data)
        assert meta["model_sha256"] == {"agent": expected.hexdigest()}  # laws have none
    out = tmp_path / "pooled"
    argv = ["dominance", *map(str, runs), "--learner", "agent", "--out", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert f"{runs[1]}: the model under agent is not the one in {runs[0]}" in err
    assert not out.exists()


def _code(digest: str | None, git: str | None) -> dict:
    """:data:`META` made by other code (``digest``), or by code it does not record (None)."""
    meta = json.loads(json.dumps(META))
    if digest is None:
        del meta["code"]
    else:
        meta["code"] = {"sources_sha256": digest, "git": git, "git_dirty": git is not None}
    return meta


def test_runs_of_the_same_code_pool_without_a_note(tmp_path: Path, capsys) -> None:
    a, b = _run(tmp_path / "a", 0, 4), _run(tmp_path / "b", 10, 4)
    out = tmp_path / "pooled"
    assert main(["dominance", str(a), str(b), "--learner", "ppo", "--out", str(out)]) == 0
    assert capsys.readouterr().err == ""
    assert "Note:" not in (out / "dominance-ppo.md").read_text()


def test_runs_of_other_code_are_pooled_with_a_warning_and_a_note(tmp_path: Path, capsys) -> None:
    a = _run(tmp_path / "a", 0, 4)
    b = _run(tmp_path / "b", 10, 4, meta=_code("beef" * 16, "fedcba987654" * 3 + "3210"))
    out = tmp_path / "pooled"
    assert main(["dominance", str(a), str(b), "--learner", "ppo", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert err.startswith("follow-eval: warning: ")
    assert f"{a} (git 1234567890ab, sources c0dec0dec0de)" in err
    assert f"{b} (git fedcba987654 + uncommitted edits, sources beefbeefbeef)" in err
    report = (out / "dominance-ppo.md").read_text().split("\n\n")
    assert report[0].startswith("Pooled from 2 runs")
    assert report[1].startswith("Note: the runs were made from different simulator, policy")


def test_a_run_that_records_no_code_is_noted_as_unknown(tmp_path: Path, capsys) -> None:
    a, b = _run(tmp_path / "a", 0, 4), _run(tmp_path / "b", 10, 4, meta=_code(None, None))
    out = tmp_path / "pooled"
    assert main(["dominance", str(a), str(b), "--learner", "ppo", "--out", str(out)]) == 0
    assert f"warning: {b}: its code revision is unknown" in capsys.readouterr().err
    report = (out / "dominance-ppo.md").read_text().split("\n\n")
    assert report[1].startswith(f"Note: {b}: its code revision is unknown")


@pytest.mark.parametrize("recorded", ["no model_sha256", "no entry"])
def test_a_run_that_records_no_digest_of_the_learners_files_is_noted_as_unknown(
    tmp_path: Path, capsys, recorded: str
) -> None:
    """Pooled by its repr alone (a path), the learner may be two models in one table: the
    report says it cannot tell (it said nothing)."""
    old = json.loads(json.dumps(META))
    if recorded == "no model_sha256":  # a run written before runs recorded the digests
        del old["model_sha256"]
    else:
        old["model_sha256"] = {}
    a, b = _run(tmp_path / "a", 0, 4), _run(tmp_path / "b", 10, 4, meta=old)
    out = tmp_path / "pooled"
    assert main(["dominance", str(a), str(b), "--learner", "ppo", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err  # one warning: the law judged records none, as laws do
    assert err.startswith(f"follow-eval: warning: {b}: the model under ppo is unknown (its ")
    assert "records no SHA-256 of its agent files" in err
    assert "cannot be checked to hold the same model under ppo" in err
    report = (out / "dominance-ppo.md").read_text().split("\n\n")
    assert report[1].startswith(f"Note: {b}: the model under ppo is unknown")


def test_runs_that_all_predate_the_digests_are_noted_by_their_learned_policys_repr(
    tmp_path: Path, capsys
) -> None:
    old = json.loads(json.dumps(META))
    del old["model_sha256"]
    a, b = _run(tmp_path / "a", 0, 4, meta=old), _run(tmp_path / "b", 10, 4, meta=old)
    out = tmp_path / "pooled"
    assert main(["dominance", str(a), str(b), "--learner", "ppo", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert f"warning: {a}, {b}: the model under ppo is unknown (their meta.json records" in err
    # a law judged against a law: no files to record, nothing to note
    argv = ["dominance", str(a), str(b), "--learner", "pn:tuned", "--laws", "gsmpn:tuned"]
    assert main([*argv, "--out", str(tmp_path / "laws")]) == 0
    assert capsys.readouterr().err == ""


def test_a_run_with_no_digest_is_noted_for_the_learner_under_perfect_sensing(
    tmp_path: Path, capsys
) -> None:
    """meta.json names the model by its own label: `ppo+ideal` (--ideal-baseline) is `ppo`'s
    model, and the note was missed for it."""
    ideal = json.loads(json.dumps(META)) | {"ideal_baseline": True}
    old = json.loads(json.dumps(ideal))
    del old["model_sha256"]
    runs = []
    for name, first, meta in (("a", 0, ideal), ("b", 10, old)):
        folder = _run(tmp_path / name, first, 4, meta=meta)
        table = pd.read_csv(folder / "episodes.csv")
        perfect = table.assign(policy=table["policy"] + "+ideal")
        pd.concat([table, perfect]).to_csv(folder / "episodes.csv", index=False)
        runs.append(str(folder))
    out = tmp_path / "pooled"
    assert main(["dominance", *runs, "--learner", "ppo+ideal", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert err.startswith(f"follow-eval: warning: {runs[1]}: the model under ppo is unknown"), err
    assert "Note: " in (out / "dominance-ppo_ideal.md").read_text()
