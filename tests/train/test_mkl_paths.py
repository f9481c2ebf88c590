"""train/mkl_paths.py: ``follow-train --mkl-intel-paths`` preloads MKL's Intel code paths.

The commands run as subprocesses: the option replaces the process (``os.execve``), which must
not be pytest's. That the library does take in torch's MKL is checked where it shows, on the
agents' actions: ``tests/policies/learned/test_networks_any_cpu.py`` (float64 the same with it,
and float32 moved by it on a CPU that is not Intel's).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from train import mkl_paths
from train.mkl_paths import OPTION, SOURCE, SYMBOL, preload_env, shim_library
from train.ppo import Args, train

ROOT = Path(__file__).resolve().parents[2]
TINY = [
    "--scenarios", "straight,curve",
    "--n-envs", "4",
    "--n-timesteps", "600",
    "--eval-freq", "400",
    "--checkpoint-freq", "400",
    "--final-episodes", "0",
    "--no-progress",
]  # fmt: skip
# Whether the library is what this process's lookup of MKL's CPU check finds, after torch.
_ACTIVE = "import torch; from train.mkl_paths import active; print(active())"


def _clean_env(**extra: str) -> dict[str, str]:
    """This process's environment without a preload (the option's or any)."""
    env = {
        k: v for k, v in os.environ.items() if k not in ("LD_PRELOAD", "PERSONFOLLOW_MKL_REEXEC")
    }
    return {**env, **extra}


def _follow_train(*argv: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "train", *argv],
        cwd=ROOT,
        env=_clean_env() if env is None else env,
        capture_output=True,
        text=True,
        timeout=600,
    )


def test_the_library_is_the_one_line_and_exports_the_check() -> None:
    library = shim_library()
    assert library.is_file()
    assert library.parent == mkl_paths.cache_dir()
    assert SOURCE == "int mkl_serv_intel_cpu_true(void) { return 1; }\n"
    # built once: a second call finds it
    assert shim_library() == library
    import ctypes

    assert ctypes.CDLL(str(library)).mkl_serv_intel_cpu_true() == 1


def test_the_lookup_finds_the_library_only_when_preloaded() -> None:
    env = _clean_env(PYTHONPATH=str(ROOT))
    without = subprocess.run([sys.executable, "-c", _ACTIVE], env=env, capture_output=True,
                             text=True, check=True)  # fmt: skip
    assert without.stdout.split() == ["False"]
    preloaded = preload_env(shim_library(), env)
    with_it = subprocess.run([sys.executable, "-c", _ACTIVE], env=preloaded,
                             capture_output=True, text=True, check=True)  # fmt: skip
    assert with_it.stdout.split() == ["True"]


def _cpu_vendor() -> str:
    for line in Path("/proc/cpuinfo").read_text(encoding="utf-8").splitlines():
        if line.startswith("vendor_id"):
            return line.split(":", 1)[1].strip()
    return ""


def test_with_the_library_mkl_takes_another_path_than_its_generic_one() -> None:
    code = "from train.mkl_paths import mkl_code_path; print(mkl_code_path())"
    env = _clean_env(PYTHONPATH=str(ROOT))
    run = [sys.executable, "-c", code]
    without = int(subprocess.run(run, env=env, capture_output=True, text=True,
                                 check=True).stdout)  # fmt: skip
    with_it = int(subprocess.run(run, env=preload_env(shim_library(), env), capture_output=True,
                                 text=True, check=True).stdout)  # fmt: skip
    assert with_it > 0
    if _cpu_vendor() == "GenuineIntel":
        assert without == with_it  # MKL's own check says Intel: nothing to change
    else:
        assert without == 0  # the generic path, which the library takes it off
    print(f"{_cpu_vendor()}: MKL code path {without} without the library, {with_it} with it")


def test_preload_env_puts_the_library_first_once() -> None:
    library = shim_library()
    env = preload_env(library, {"LD_PRELOAD": f"/x/libother.so {library}", "A": "1"})
    assert env == {"LD_PRELOAD": f"{library}:/x/libother.so", "A": "1"}
    assert preload_env(library, {}) == {"LD_PRELOAD": str(library)}


@pytest.mark.slow
def test_a_run_with_the_option_trains_preloaded_and_records_it(tmp_path: Path) -> None:
    run = tmp_path / "run"
    done = _follow_train(OPTION, *TINY, "--out", str(run))
    assert done.returncode == 0, done.stderr
    config = yaml.safe_load((run / "config.yaml").read_text(encoding="utf-8"))
    assert config["args"]["mkl_intel_paths"] is True
    assert config["command"].startswith(f"follow-train {OPTION} --scenarios")
    # A resume may give the option anew (as --threads); each session records its own.
    resumed = _follow_train("--resume", str(run), "--n-timesteps", "1000", "--no-progress")
    assert resumed.returncode == 0, resumed.stderr
    sessions = json.loads((run / "sessions.json").read_text(encoding="utf-8"))
    assert [s["mkl_intel_paths"] for s in sessions] == [True, False]


@pytest.mark.slow
def test_a_studys_workers_train_preloaded(tmp_path: Path) -> None:
    # Each seed's worker refuses to train without the library (require_active), so a study
    # that finishes ran every seed with it.
    study = tmp_path / "study"
    done = _follow_train(OPTION, *TINY, "--seeds", "0-1", "--workers", "2", "--out", str(study))
    assert done.returncode == 0, done.stderr
    for k in (0, 1):
        config = yaml.safe_load((study / f"seed-{k}" / "config.yaml").read_text("utf-8"))
        assert config["args"]["mkl_intel_paths"] is True


@pytest.mark.slow
def test_the_ppo_searchs_trials_train_preloaded(tmp_path: Path) -> None:
    out = tmp_path / "search"
    argv = ["-m", "train.tune", OPTION, "--trials", "1", "--n-timesteps", "256", "--n-envs", "12"]
    argv += ["--seeds", "1", "--scenarios", "straight", "--out", str(out)]
    done = subprocess.run([sys.executable, *argv], cwd=ROOT, env=_clean_env(),
                          capture_output=True, text=True, timeout=600)  # fmt: skip
    assert done.returncode == 0, done.stderr
    (sessions,) = out.glob("trials/*/run/sessions.json")
    assert json.loads(sessions.read_text(encoding="utf-8"))[-1]["mkl_intel_paths"] is True


def test_a_run_in_a_process_without_the_library_is_refused_before_writing(tmp_path: Path) -> None:
    if mkl_paths.active():
        pytest.skip("this test process runs with the library preloaded")
    run = tmp_path / "run"
    args = Args(mkl_intel_paths=True, scenarios=("straight",), n_envs=4, n_timesteps=100,
                out=run, progress=False)  # fmt: skip
    with pytest.raises(ValueError, match=f"^{OPTION}: ") as e:
        train(args)
    library = shim_library()
    assert str(e.value).startswith(f"{OPTION}: this process (")
    assert f"runs without {library} preloaded" in str(e.value)
    assert f"LD_PRELOAD={library}" in str(e.value)
    assert not run.exists()


def test_a_preload_that_does_not_take_stops_instead_of_looping(tmp_path: Path) -> None:
    # The command was run again once with the library and it still did not take.
    env = _clean_env(PERSONFOLLOW_MKL_REEXEC=str(shim_library()))
    done = _follow_train(OPTION, *TINY, "--out", str(tmp_path / "run"), env=env)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        f"follow-train: error: {OPTION}: {shim_library()} was preloaded (LD_PRELOAD) and MKL "
        f"still finds its own {SYMBOL}; this Python or torch build does not let it be replaced"
    ]
    assert not (tmp_path / "run").exists()


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
