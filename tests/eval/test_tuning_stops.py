"""follow-tune and follow-eval run: a cluster that does not answer, SIGTERM, ``--write-preset``
onto a file of someone else's, a database driver that is missing, and strict JSON.

Each once went wrong: ``--address auto`` read a stale Ray address file (or named a port where
another service listens) and hung for minutes, with ``--workers`` after writing a journal; SIGTERM
ended a study with Python's default (no message, a lock file sometimes left, exit status -15);
``--write-preset policies/pn.py`` replaced the module; ``postgresql://`` failed with Optuna's
generic import message; a held-out check of one episode wrote NaN into ``result.json``. The
commands run as real processes where a hang or a signal is what is tested.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from eval import tune
from eval.journal import journal_folder
from eval.tuning.cli import main
from execution.ray_address import GCS_ANSWER_S
from tests.eval.test_tuning_cli_errors import SMALL, _refused, _tree
from tests.execution.test_ray_address import (
    Listener,
    closed_port,
    require_no_ray_here,
    stale_address_file,
)

ROOT = Path(__file__).resolve().parents[2]
TUNE = [sys.executable, "-m", "eval.tuning.cli"]
EVAL = [sys.executable, "-m", "eval"]


def _env(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "RAY_ADDRESS"}
    env["RAY_USAGE_STATS_ENABLED"] = "0"
    return env | extra


def _one_line_exit_2(argv: list[str], env: dict[str, str], within_s: float) -> str:
    """Run ``argv``; assert exit status 2 and one stderr line, within ``within_s`` seconds (a
    hang is ended there, and fails)."""
    started = time.monotonic()
    done = subprocess.run(argv, cwd=ROOT, env=env, capture_output=True, text=True, timeout=within_s)
    assert done.returncode == 2, done.stderr
    assert done.stderr.count("\n") == 1, done.stderr
    assert time.monotonic() - started < within_s
    return done.stderr


@pytest.fixture
def silent() -> Iterator[Listener]:
    listener = Listener()
    yield listener
    listener.close()


# 1. A cluster that does not answer: one line, exit status 2, nothing written, in bounded time.


@pytest.mark.slow
@pytest.mark.before_ray  # conftest: before the session's Ray, which auto would take
def test_auto_from_a_stale_address_file_writes_no_journal(
    tmp_path: Path, request: pytest.FixtureRequest
) -> None:
    require_no_ray_here(request)
    stale_address_file(tmp_path / "raytmp", f"127.0.0.1:{closed_port()}")
    env = _env(RAY_TMPDIR=str(tmp_path / "raytmp"))
    out = tmp_path / "out"
    argv = [*TUNE, "pn", *SMALL, "--backend", "ray", "--address", "auto", "--workers", "2"]
    err = _one_line_exit_2([*argv, "--out", str(out)], env, 60)
    assert err.startswith("follow-tune: error: cannot reach the Ray cluster at auto (")
    assert "ray_current_cluster" in err
    assert not out.exists()
    ev = tmp_path / "ev"
    argv = [*EVAL, "run", "--policies", "pn", "--scenarios", "straight", "--episodes", "1"]
    argv += ["--backend", "ray", "--address", "auto", "--workers", "1", "--out", str(ev)]
    err = _one_line_exit_2(argv, env, 60)
    assert err.startswith("follow-eval: error: cannot reach the Ray cluster at auto (")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["raytmp"]


@pytest.mark.slow
def test_a_port_that_is_no_ray_gcs_is_refused_within_the_deadline(
    tmp_path: Path, silent: Listener
) -> None:
    out = tmp_path / "out"
    address = f"127.0.0.1:{silent.port}"
    argv = [*TUNE, "pn", *SMALL, "--backend", "ray", "--address", address, "--workers", "2"]
    err = _one_line_exit_2([*argv, "--out", str(out)], _env(), GCS_ANSWER_S + 20)
    assert f"cannot reach the Ray cluster at {address} (" in err
    assert "no Ray GCS answers" in err
    assert not out.exists()


# 2. SIGTERM takes Ctrl-C's path: one line, the study's locks released, exit status 143.


def _term_when(
    proc: subprocess.Popen[str], ready: Callable[[], bool], wait_s: float, deadline_s: float = 120
) -> str:
    """SIGTERM ``proc`` ``wait_s`` seconds after ``ready()`` holds; its stderr."""
    deadline = time.monotonic() + deadline_s
    while not ready() and proc.poll() is None:
        assert time.monotonic() < deadline, f"not ready in {deadline_s} s"
        time.sleep(0.05)
    time.sleep(wait_s)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    return err


@pytest.mark.slow
@pytest.mark.parametrize("backend", [["--workers", "1"], ["--backend", "ray", "--workers", "1"]])
def test_sigterm_stops_a_study_as_ctrl_c_does(tmp_path: Path, backend: list[str]) -> None:
    out = tmp_path / "out"
    argv = [*TUNE, "pn", "--trials", "300", "--seeds", "12", *backend, "--out", str(out)]
    proc = subprocess.Popen(
        argv, cwd=ROOT, env=_env(), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
    )
    err = _term_when(proc, (out / "study.journal").exists, 1.0)  # into the search
    assert proc.returncode == 143, err
    last = err.strip().splitlines()[-1]
    assert last.startswith("follow-tune: terminated (SIGTERM); the study pn-person_follow in ")
    assert last.endswith("run the same command again to resume")
    assert "Traceback" not in err
    assert "SIGTERM received" not in err  # Ray's C++ stack dump
    assert sorted(p.name for p in out.iterdir()) == ["study.journal"]  # no lock left


@pytest.mark.slow
def test_sigterm_stops_follow_eval_run_as_ctrl_c_does(tmp_path: Path) -> None:
    out = tmp_path / "run"
    # enough units that SIGTERM lands while they run, not in the tables written after them
    grid = ["--policies", "pn,mpn", "--scenarios", "straight,curve", "--episodes", "40"]
    proc = subprocess.Popen(
        [*EVAL, "run", *grid, "--workers", "1", "--out", str(out)],
        cwd=ROOT,
        env=_env(),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    err = _term_when(proc, lambda: any(journal_folder(out).glob("unit-*.pkl")), 0.0)
    assert proc.returncode == 143, err
    assert (
        err.strip()
        .splitlines()[-1]
        .startswith(f"follow-eval: terminated (SIGTERM); {out} was not written.")
    )
    assert not out.exists()


# 3. --write-preset replaces only a preset follow-tune wrote, and the closing line names it.


def test_write_preset_onto_another_file_is_refused_unchanged(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    module = tmp_path / "pn.py"
    module.write_text('"""My law module."""\nPRESETS = {}\n')
    before = _tree(tmp_path)
    argv = ["pn", *SMALL, "--out", str(tmp_path / "out"), "--write-preset", str(module)]
    _refused(capsys, argv, f"--write-preset {module}: the file exists and is not a preset")
    assert _tree(tmp_path) == before


def test_a_one_episode_check_writes_strict_json_and_names_the_preset_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    preset = tmp_path / "pn_preset.txt"
    out = tmp_path / "out"
    argv = ["pn", *SMALL, "--workers", "1", "--out", str(out), "--write-preset", str(preset)]
    assert main(argv) == 0
    assert (
        capsys.readouterr()
        .out.splitlines()[-1]
        .endswith(f"Wrote {out}/result.json, preset.txt and {preset}")
    )
    assert main(argv) == 0  # a preset follow-tune wrote may be written again

    def refuse(constant: str) -> None:
        raise AssertionError(f"result.json holds {constant}")

    # one held-out episode: no interval, written as null (NaN is not JSON)
    summary = json.loads((out / "result.json").read_text(), parse_constant=refuse)
    assert any(row["ci_low"] is None for row in summary["holdout"])


# 4. A database URL whose driver is missing names the package to install.


@pytest.mark.parametrize(
    ("url", "package"),
    [
        ("postgresql+psycopg2://user@db/tuning", "pip install psycopg2-binary"),
        ("mysql+pymysql://user@db/tuning", "pip install PyMySQL"),
    ],
)
def test_a_missing_database_driver_names_its_package(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], url: str, package: str
) -> None:
    module = url.partition("+")[2].partition(":")[0]
    try:
        __import__(module)
    except ImportError:
        pass
    else:
        pytest.skip(f"{module} is installed")
    argv = ["pn", *SMALL, "--storage", url, "--out", str(tmp_path / "out")]
    _refused(capsys, argv, f"--storage {url}: ", f"({module}) is not installed", package)
    assert not any(tmp_path.iterdir())


# 5. python -m eval.tune --help is its own.


def test_eval_tune_help_is_its_own(capsys: pytest.CaptureFixture[str]) -> None:
    assert tune.main(["--help"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: python -m eval.tune [-h] [--out-root DIR]")
    assert "pn, mpn, gsmpn" in out
