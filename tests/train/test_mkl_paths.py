"""train/mkl_paths.py: ``follow-train --mkl-intel-paths`` preloads MKL's Intel code paths.

The commands run as subprocesses: the option replaces the process (``os.execve``), which must
not be pytest's. That the library takes in torch's MKL is checked by the code path MKL reports
(here) and on the agents' actions: ``tests/policies/learned/test_networks_any_cpu.py`` (float64
the same with it; float32 moved by it on a CPU that is not Intel's, not on an Intel one). The
library is built into a folder of this module's own (``XDG_CACHE_HOME``), not the user's cache.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
import yaml

from train import mkl_paths
from train.cli import main
from train.mkl_paths import OPTION, SOURCE, SYMBOL, cpu_vendor, plain_env, preload_env, shim_library
from train.options import Args as OptionArgs
from train.ppo import Args, train
from train.study_lock import StudyLock
from train.study_record import CODE, STUDY, claim, study_settings

ROOT = Path(__file__).resolve().parents[2]
FOLLOW_TRAIN = Path(sys.executable).with_name("follow-train")
TINY = [
    "--scenarios", "straight,curve",
    "--n-envs", "4",
    "--n-timesteps", "600",
    "--eval-freq", "100000",  # no held-out evaluation: the runs are about the option
    "--checkpoint-freq", "400",
    "--final-episodes", "0",
    "--no-progress",
]  # fmt: skip

try:
    mkl_paths.check_platform()
except ValueError as e:
    pytest.skip(str(e), allow_module_level=True)
if mkl_paths.c_compiler() is None:
    pytest.skip("no C compiler (cc, gcc) to build the library", allow_module_level=True)


@pytest.fixture(autouse=True, scope="module")
def _cache(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """The library's cache folder for this module (inherited by the commands it runs)."""
    folder = tmp_path_factory.mktemp("xdg-cache")
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("XDG_CACHE_HOME", str(folder))
        yield folder


def _clean_env(**extra: str) -> dict[str, str]:
    """This process's environment without a preload (the option's or any), plus ``extra``."""
    return {**plain_env(), **extra}


def _run(argv: list[str], cwd: Path = ROOT, env: dict[str, str] | None = None) -> (
    subprocess.CompletedProcess[str]
):  # fmt: skip
    return subprocess.run(
        argv,
        cwd=cwd,
        env=_clean_env() if env is None else env,
        capture_output=True,
        text=True,
        timeout=600,
    )


def _follow_train(*argv: str, env: dict[str, str] | None = None) -> (
    subprocess.CompletedProcess[str]
):  # fmt: skip
    return _run([sys.executable, "-m", "train", *argv], env=env)


def _sessions(run: Path) -> list[dict]:
    return json.loads((run / "sessions.json").read_text(encoding="utf-8"))


def test_the_library_is_the_one_line_and_answers_yes() -> None:
    library = shim_library()
    assert library.is_file()
    assert library.parent == Path(os.environ["XDG_CACHE_HOME"]) / "personfollow"
    assert SOURCE == "int mkl_serv_intel_cpu_true(void) { return 1; }\n"
    assert shim_library() == library  # built once: a second call finds it
    import ctypes

    assert getattr(ctypes.CDLL(str(library)), SYMBOL)() == 1


def test_a_damaged_library_is_built_again() -> None:
    library = shim_library()
    # a new file in its place (the loaded one must not be written over: it is mapped)
    damaged = library.with_suffix(".damaged")
    damaged.write_bytes(b"not a shared object")
    os.replace(damaged, library)
    assert shim_library() == library
    assert library.read_bytes()[:4] == b"\x7fELF"


def test_the_lookup_finds_a_preloaded_library_wherever_it_lies(tmp_path: Path) -> None:
    code = "import torch; from train.mkl_paths import active; print(active())"
    env = _clean_env(PYTHONPATH=str(ROOT))
    assert _run([sys.executable, "-c", code], env=env).stdout.split() == ["False"]
    copy = tmp_path / "elsewhere.so"
    shutil.copy(shim_library(), copy)
    for library in (shim_library(), copy):
        done = _run([sys.executable, "-c", code], env=preload_env(library, env))
        assert done.stdout.split() == ["True"], done.stderr


def test_with_the_library_mkl_takes_another_path_than_its_generic_one() -> None:
    code = "from train.mkl_paths import mkl_code_path; print(mkl_code_path())"
    env = _clean_env(PYTHONPATH=str(ROOT))
    without = int(_run([sys.executable, "-c", code], env=env).stdout)
    with_it = int(_run([sys.executable, "-c", code], env=preload_env(shim_library(), env)).stdout)
    assert with_it > 0
    if cpu_vendor() == "GenuineIntel":
        assert without == with_it  # MKL's own check says Intel: nothing to change
    else:
        assert without == 0  # the generic path, which the library takes it off
    print(f"{cpu_vendor()}: MKL code path {without} without the library, {with_it} with it")


def test_preload_env_puts_the_library_first_once() -> None:
    library = shim_library()
    env = preload_env(library, {"LD_PRELOAD": f"/x/libother.so {library}", "A": "1"})
    assert env == {"LD_PRELOAD": f"{library}:/x/libother.so", "A": "1"}
    assert preload_env(library, {}) == {"LD_PRELOAD": str(library)}


@pytest.mark.slow
def test_a_run_with_the_option_trains_preloaded_and_records_it(tmp_path: Path) -> None:
    # From a folder with a train.py, which `python -m train` would run: the command runs again
    # as the user ran it (here the console script), so it does not.
    (tmp_path / "train.py").write_text("raise SystemExit('the folder train.py ran')\n")
    run = tmp_path / "run"
    done = _run([str(FOLLOW_TRAIN), OPTION, *TINY, "--out", str(run)], cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    config = yaml.safe_load((run / "config.yaml").read_text(encoding="utf-8"))
    assert config["args"]["mkl_intel_paths"] is True
    assert config["command"].startswith(f"follow-train {OPTION} --scenarios")
    # A resume may give the option anew (as --threads); each session records its own, and the
    # code path MKL reported.
    resumed = _follow_train("--resume", str(run), "--n-timesteps", "1000", "--no-progress")
    assert resumed.returncode == 0, resumed.stderr
    sessions = _sessions(run)
    assert [s["mkl_intel_paths"] for s in sessions] == [True, False]
    assert sessions[0]["mkl_code_path"] > 0
    if cpu_vendor() != "GenuineIntel":
        assert sessions[1]["mkl_code_path"] == 0


@pytest.mark.slow
def test_a_studys_workers_train_preloaded(tmp_path: Path) -> None:
    # Each seed's worker refuses to train without the library (require_active), so a study
    # that finishes ran every seed with it (a resumed seed keeps the option too:
    # tests/train/test_seed_units.py).
    study = tmp_path / "study"
    done = _follow_train(OPTION, *TINY, "--seeds", "0-1", "--workers", "2", "--out", str(study))
    assert done.returncode == 0, done.stderr
    for k in (0, 1):
        assert [s["mkl_intel_paths"] for s in _sessions(study / f"seed-{k}")] == [True]


def test_the_option_is_no_part_of_what_a_study_is(tmp_path: Path) -> None:
    # as --threads: studies written before it had no such key, and stay resumable
    with_it = study_settings(OptionArgs(mkl_intel_paths=True), (0, 1))
    assert with_it == study_settings(OptionArgs(), (0, 1))
    assert "mkl_intel_paths" not in with_it
    # and a study.json written while it counted (it did, briefly) is still this study's
    study = tmp_path / "study"
    study.mkdir()
    code = "0" * 64
    (study / STUDY).write_text(json.dumps({**with_it, "mkl_intel_paths": True, CODE: code}))
    with StudyLock(study) as lock:
        claim(study, with_it, code, lock, training=True)  # no "holds another study"


class _RanAgainError(Exception):
    """Stands for the process being replaced."""


def test_the_ppo_search_runs_again_preloaded_and_its_trials_ask_for_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # In this process: the search's command is run again (as follow-train's, tested above by a
    # real command), and once preloaded its trials train with the option, so that each trial's
    # run refuses to train without it (require_active).
    import train.tune as tune

    argv = [OPTION, "--trials", "1", "--n-timesteps", "256", "--n-envs", "12", "--seeds", "1"]
    argv += ["--scenarios", "straight", "--out", str(tmp_path / "search")]
    ran_again: list[list[str]] = []

    def reexec(given: list[str]) -> None:
        ran_again.append(list(given))
        raise _RanAgainError

    monkeypatch.setattr(mkl_paths, "active", lambda: False)
    monkeypatch.setattr(mkl_paths, "reexec", reexec)
    with pytest.raises(_RanAgainError):
        tune.main(argv)
    assert ran_again == [argv]
    assert not (tmp_path / "search").exists()  # nothing written before it runs again
    trials: list[Args] = []

    def objective(base: Args, *rest: object) -> None:
        trials.append(base)
        raise _RanAgainError

    monkeypatch.setattr(mkl_paths, "active", lambda: True)
    monkeypatch.setattr(tune, "PPOObjective", objective)
    with pytest.raises(_RanAgainError):
        tune.main(argv)
    assert trials[0].mkl_intel_paths is True


def test_main_called_from_python_is_refused_not_replaced(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    if mkl_paths.active():
        pytest.skip("this test process runs with the library preloaded")
    run = tmp_path / "run"
    assert main([OPTION, *TINY, "--out", str(run)]) == 2
    assert capsys.readouterr().err == (
        f"follow-train: error: {OPTION}: runs the command again preloaded, so it needs this "
        "process's own command line; from Python, start the process with LD_PRELOAD set to "
        "train.mkl_paths.shim_library() instead\n"
    )
    assert not run.exists()


def test_a_run_in_a_process_without_the_library_is_refused_before_writing(tmp_path: Path) -> None:
    if mkl_paths.active():
        pytest.skip("this test process runs with the library preloaded")
    run = tmp_path / "run"
    args = Args(mkl_intel_paths=True, scenarios=("straight",), n_envs=4, n_timesteps=100,
                out=run, progress=False)  # fmt: skip
    with pytest.raises(ValueError, match=f"^{OPTION}: this process ") as e:
        train(args)
    assert "runs without the library preloaded" in str(e.value)
    assert f"(follow-train builds it at {mkl_paths.library_path()} on this machine)" in str(e.value)
    assert not run.exists()


def test_a_preload_that_does_not_take_stops_instead_of_looping(tmp_path: Path) -> None:
    # The command ran again once with the library and it still did not take.
    library = shim_library()
    env = _clean_env(PERSONFOLLOW_MKL_REEXEC=str(library))
    done = _follow_train(OPTION, *TINY, "--out", str(tmp_path / "run"), env=env)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        f"follow-train: error: {OPTION}: the command ran again with LD_PRELOAD={library} and "
        f"this process still does not find its {SYMBOL} (a message from ld.so above, if any, "
        "says why)"
    ]
    assert not (tmp_path / "run").exists()


def test_usage_errors_come_before_the_library(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(mkl_paths.shutil, "which", lambda name: None)  # no compiler either
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "empty-cache"))
    assert main([OPTION, "--n-timesteps", "0"]) == 2
    assert capsys.readouterr().err == (
        "follow-train: error: --n-timesteps 0 is out of range: must be an integer >= 1\n"
    )


def test_no_compiler_is_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.setattr(mkl_paths.shutil, "which", lambda name: None)
    with pytest.raises(ValueError, match=r"^--mkl-intel-paths: no C compiler found \(cc, gcc"):
        shim_library()
    assert not (tmp_path / "cache").exists()


def test_a_compiler_that_fails_says_so_and_leaves_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    cache = tmp_path / "cache"
    monkeypatch.setenv("XDG_CACHE_HOME", str(cache))
    failing = shutil.which("false")  # a compiler that fails without a word
    assert failing is not None
    monkeypatch.setenv("CC", failing)
    with pytest.raises(ValueError, match=f"^{OPTION}: ") as e:
        shim_library()
    assert re.fullmatch(
        rf"--mkl-intel-paths: {re.escape(failing)} could not build "
        r"libmkl_intel_paths-[0-9a-f]{12}\.so \(exit status 1\)",
        str(e.value),
    ), str(e.value)
    assert list((cache / "personfollow").iterdir()) == []


def test_a_cache_path_ld_preload_cannot_hold_is_refused(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    spaced = tmp_path / "a b"
    monkeypatch.setenv("XDG_CACHE_HOME", str(spaced))
    with pytest.raises(ValueError, match=f"^{OPTION}: ") as e:
        shim_library()
    assert str(e.value) == (
        f"{OPTION}: the library's folder {spaced}/personfollow has a space or a colon in its "
        "path, which LD_PRELOAD cannot hold; set XDG_CACHE_HOME to a folder without them"
    )
    assert not spaced.exists()


def test_an_unwritable_cache_says_which_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("not a folder", encoding="utf-8")
    monkeypatch.setenv("XDG_CACHE_HOME", str(blocker))
    with pytest.raises(ValueError, match=rf"cannot write the library into {blocker}/personfollow"):
        shim_library()


@pytest.mark.parametrize(("system", "machine"), [("darwin", "arm64"), ("linux", "aarch64")])
def test_other_platforms_are_refused(
    monkeypatch: pytest.MonkeyPatch, system: str, machine: str
) -> None:
    monkeypatch.setattr(mkl_paths.sys, "platform", system)
    monkeypatch.setattr(mkl_paths.platform, "machine", lambda: machine)
    with pytest.raises(ValueError, match=f"^{OPTION}: ") as e:
        shim_library()
    assert str(e.value) == (
        f"--mkl-intel-paths: this is {system} on {machine}; the option applies on Linux on "
        "x86-64 only, where torch's CPU build carries Intel's MKL"
    )


def test_beside_add_step_it_is_refused(tmp_path: Path) -> None:
    done = _follow_train("--add-step", str(tmp_path), "--step", "{a: {}}", OPTION)
    assert done.returncode == 2
    assert done.stderr.strip() == (
        "follow-train: error: --mkl-intel-paths: --add-step trains nothing; it takes --step, "
        "--before and --force only"
    )


# The trust checks: whatever is in the library runs in every process the option starts.


def _as_owned_by(monkeypatch: pytest.MonkeyPatch, path: Path | None, uid: int) -> None:
    """``os.lstat`` reports ``path`` (every path: None) as owned by ``uid`` (the tests cannot
    chown as any user)."""
    real = os.lstat

    def lstat(p: os.PathLike[str] | str, *args: object, **kwargs: object) -> os.stat_result:
        st = real(p, *args, **kwargs)  # type: ignore[arg-type]
        if path is not None and Path(p) != path:
            return st
        fields = list(st[:10])
        fields[4] = uid  # st_uid
        return os.stat_result(fields)

    monkeypatch.setattr(mkl_paths.os, "lstat", lstat)


def _not_loaded(monkeypatch: pytest.MonkeyPatch) -> list[Path]:
    """The libraries ``shim_library`` loads to check them, from now on."""
    loaded: list[Path] = []
    real = mkl_paths._answers_yes
    monkeypatch.setattr(mkl_paths, "_answers_yes", lambda p: loaded.append(p) or real(p))
    return loaded


def _refusal() -> str:
    """The one-line message ``shim_library`` refuses with."""
    with pytest.raises(ValueError, match=f"^{OPTION}: ") as e:
        shim_library()
    return str(e.value)


def test_the_folder_is_the_users_alone_and_the_library_not_writable_by_others(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    old = os.umask(0o002)  # a user-private-group umask: group-writable files by default
    try:
        library = shim_library()
    finally:
        os.umask(old)
    assert library.parent.stat().st_mode & 0o777 == 0o700
    assert library.stat().st_mode & 0o777 == 0o755


def test_an_earlier_versions_group_writable_cache_is_mended(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Built under umask 002 before the checks: the folder loses the group's write, and the
    library, which the group could have changed, is built again without being loaded."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    library = shim_library()
    library.parent.chmod(0o775)
    library.chmod(0o775)
    old = tmp_path / "old.so"
    os.link(library, old)  # holds the old file, so that the new one cannot reuse its inode
    loaded = _not_loaded(monkeypatch)
    assert shim_library() == library
    assert library.parent.stat().st_mode & 0o777 == 0o755
    assert library.stat().st_mode & 0o777 == 0o755
    assert not library.samefile(old)  # a new file
    assert old.stat().st_nlink == 1
    assert loaded == []  # the new one is trusted as built; the old one never loaded


@pytest.mark.parametrize("which", ["library", "folder"])
def test_a_cache_of_another_user_is_refused_before_anything_loads(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, which: str
) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    library = shim_library()
    path = library if which == "library" else library.parent
    other = os.geteuid() + 1
    _as_owned_by(monkeypatch, path, other)
    loaded = _not_loaded(monkeypatch)
    assert _refusal() == (
        f"{OPTION}: {path} belongs to user id {other}, neither this user ({os.geteuid()}) nor "
        "root, who could replace the library it preloads; set XDG_CACHE_HOME to a folder of "
        "your own"
    )
    assert loaded == []
    assert library.is_file()  # another user's file is left alone


@pytest.mark.parametrize("which", ["library", "folder"])
def test_roots_cache_is_used_but_not_if_others_can_write_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, which: str
) -> None:
    """A cache root built (in an image, say) serves every user; one others can write does not,
    and is not this user's to mend."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    library = shim_library()
    _as_owned_by(monkeypatch, None, 0)  # every path root's
    monkeypatch.setattr(mkl_paths.os, "geteuid", lambda: 4321)
    assert shim_library() == library
    path = library if which == "library" else library.parent
    path.chmod(0o775)
    loaded = _not_loaded(monkeypatch)
    assert _refusal() == (
        f"{OPTION}: {path} belongs to root and can be written by other users (mode 0o775); set "
        "XDG_CACHE_HOME to a folder of your own"
    )
    assert loaded == []
    assert path.stat().st_mode & 0o777 == 0o775  # left as it was


def test_a_folder_above_that_others_can_write_is_refused_unless_sticky(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    above = tmp_path / "shared"
    above.mkdir()
    above.chmod(0o777)
    monkeypatch.setenv("XDG_CACHE_HOME", str(above / "cache"))
    assert _refusal() == (
        f"{OPTION}: {above} can be written by other users (mode 0o777, no sticky bit), who could "
        "replace the library in a folder below it; set XDG_CACHE_HOME to a folder only you can "
        "write"
    )
    assert list(above.iterdir()) == []  # nothing built
    above.chmod(0o1777)  # as /tmp: no one renames another's folder away
    assert shim_library().is_file()


def test_a_folder_above_of_another_user_is_refused(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    above = tmp_path / "theirs"
    above.mkdir()
    monkeypatch.setenv("XDG_CACHE_HOME", str(above))
    other = os.geteuid() + 1
    _as_owned_by(monkeypatch, above, other)
    with pytest.raises(ValueError, match=rf"^{OPTION}: {above} belongs to user id {other},"):
        shim_library()
    assert list(above.iterdir()) == []


def test_a_link_of_another_user_on_the_way_is_refused(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    real = tmp_path / "real"
    real.mkdir()
    link = tmp_path / "link"
    link.symlink_to(real)
    monkeypatch.setenv("XDG_CACHE_HOME", str(link))
    assert shim_library().parent == link / "personfollow"  # this user's link: followed
    other = os.geteuid() + 1
    _as_owned_by(monkeypatch, link, other)
    with pytest.raises(ValueError, match=rf"^{OPTION}: {link} belongs to user id {other},"):
        shim_library()


def test_a_folder_made_by_another_user_meanwhile_is_not_built_into(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Between the first check and ``mkdir``, another user makes the folder: checked again."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    folder = tmp_path / "personfollow"
    other = os.geteuid() + 1
    real_compiler = mkl_paths.c_compiler

    def compiler_after_the_other_user() -> str | None:
        folder.mkdir()
        folder.chmod(0o777)
        _as_owned_by(monkeypatch, folder, other)
        return real_compiler()

    monkeypatch.setattr(mkl_paths, "c_compiler", compiler_after_the_other_user)
    with pytest.raises(ValueError, match=rf"^{OPTION}: {folder} belongs to user id {other},"):
        shim_library()
    assert list(folder.iterdir()) == []  # nothing built into it


def test_a_cache_path_that_is_a_file_says_so(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    (tmp_path / "personfollow").write_text("not a folder", encoding="utf-8")
    assert _refusal() == f"{OPTION}: {tmp_path / 'personfollow'} is not a folder; remove it"


def test_follow_train_refuses_an_untrusted_cache_in_one_line(tmp_path: Path) -> None:
    above = tmp_path / "shared"
    above.mkdir()
    above.chmod(0o777)
    out = tmp_path / "run"
    done = _follow_train(
        *TINY, "--out", str(out), OPTION, env=_clean_env(XDG_CACHE_HOME=str(above / "cache"))
    )
    assert done.returncode == 2, done.stderr
    assert done.stderr.count("\n") == 1, done.stderr
    assert done.stderr.startswith(
        f"follow-train: error: {OPTION}: {above} can be written by other users (mode 0o777, "
    ), done.stderr
    assert not out.exists()
    assert list(above.iterdir()) == []
