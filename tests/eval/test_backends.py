"""``follow-eval run`` on every backend writes the same files, and an interrupted run resumes.

Ray runs on a local instance of 2 CPUs (the ``local_ray`` fixture) and, for the README's "On a
cluster" commands, on a head and a worker started with ``ray start`` on 127.0.0.1.
"""

from __future__ import annotations

import json
import os
import secrets
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from eval.cli import main
from eval.journal import journal_folder

GRID = ["--policies", "pn,mpn,gsmpn", "--scenarios", "straight,curve,random", "--episodes", "3"]
ROOT = Path(__file__).resolve().parents[2]


def _files(run: Path) -> dict[str, bytes]:
    """Every file of a run folder but those that say when and how it ran (meta.json, and the
    copy of it in summary.json)."""
    out = {}
    for path in sorted(run.rglob("*")):
        name = path.relative_to(run).as_posix()
        if path.is_file() and name != "meta.json":
            out[name] = path.read_bytes()
    summary = json.loads(out.pop("summary.json"))
    summary.pop("meta")
    out["summary.json (without meta)"] = json.dumps(summary).encode()
    return out


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory) -> dict[str, bytes]:
    out = tmp_path_factory.mktemp("local") / "run"
    assert main(["run", *GRID, "--out", str(out), "--workers", "1"]) == 0
    return _files(out)


@pytest.mark.slow
def test_ray_writes_the_same_files_byte_for_byte(
    reference: dict[str, bytes], local_ray, tmp_path: Path
) -> None:
    out = tmp_path / "ray"
    assert main(["run", *GRID, "--out", str(out), "--backend", "ray"]) == 0
    got = _files(out)
    assert got.keys() == reference.keys()
    assert len([n for n in got if n.startswith("logs/")]) == 27
    for name, data in reference.items():
        assert got[name] == data, name
    assert json.loads((out / "meta.json").read_text())["backend"]["kind"] == "ray"


@pytest.mark.slow
def test_ray_without_logs_writes_the_same_tables_and_plots(
    reference: dict[str, bytes], local_ray, tmp_path: Path
) -> None:
    out = tmp_path / "ray"
    assert main(["run", *GRID, "--out", str(out), "--backend", "ray", "--no-logs"]) == 0
    got = _files(out)  # the rows made in Ray's workers, the plot seed's episodes kept whole
    assert got.keys() == {name for name in reference if not name.startswith("logs/")}
    for name, data in got.items():
        assert data == reference[name], name


@pytest.mark.slow
def test_metrics_on_ray_writes_the_same_tables(local_ray, tmp_path: Path) -> None:
    run = tmp_path / "run"
    assert main(["run", *GRID, "--out", str(run), "--workers", "1"]) == 0
    local, ray = tmp_path / "local", tmp_path / "ray"
    assert main(["metrics", str(run / "logs"), "--out", str(local), "--workers", "1"]) == 0
    assert main(["metrics", str(run / "logs"), "--out", str(ray), "--backend", "ray"]) == 0
    for name in ("summary.csv", "episodes.csv", "comparisons.csv"):
        assert (ray / name).read_bytes() == (local / name).read_bytes(), name


@pytest.mark.slow
def test_ctrl_c_writes_nothing_and_the_same_command_resumes(
    reference: dict[str, bytes], tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    out = tmp_path / "run"
    args = ["run", *GRID, "--out", str(out), "--workers", "1"]
    journal = journal_folder(out)
    proc = subprocess.Popen(
        [sys.executable, "-m", "eval", *args],
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 120
    while not any(journal.glob("unit-*.pkl")) and proc.poll() is None:
        assert time.monotonic() < deadline, "no work unit finished in 2 minutes"
        time.sleep(0.01)
    proc.send_signal(signal.SIGINT)  # Ctrl-C, after the first unit of nine
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "run the same command again to resume" in err
    assert not out.exists()
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]  # no half folder
    kept = len(list(journal.glob("unit-*.pkl")))
    assert 1 <= kept < 9

    assert main(args) == 0
    assert f"resuming: {kept} work units already done" in capsys.readouterr().err
    assert _files(out) == reference
    assert not journal.exists()  # removed once the run's folder is written


def test_a_journal_of_another_run_is_refused_by_name(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    out = tmp_path / "run"
    journal = journal_folder(out)
    journal.mkdir()
    (journal / "run.json").write_text('{"task": "person_follow", "policies": ["pn"]}')
    assert main(["run", *GRID, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert str(journal) in err
    assert "another run" in err
    assert err.count("\n") == 1


def test_ray_options_are_checked_before_any_work(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    assert main(["run", *GRID, "--out", str(tmp_path / "a"), "--address", "x:1"]) == 2
    assert "--address is for --backend ray" in capsys.readouterr().err
    assert main(["run", *GRID, "--out", str(tmp_path / "b"), "--backend", "slurm"]) == 2
    assert "invalid choice: 'slurm'" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow
def test_the_readme_cluster_commands_run_on_loopback(
    reference: dict[str, bytes], tmp_path: Path
) -> None:
    """README "On a cluster": a head and a worker on 127.0.0.1, the evaluation sent to them."""
    pytest.importorskip("ray")
    ray = Path(sys.executable).with_name("ray")
    port = _free_port()
    env = os.environ | {
        "RAY_AUTH_MODE": "token",
        "RAY_AUTH_TOKEN": secrets.token_hex(32),  # every node and the driver share it
        "RAY_USAGE_STATS_ENABLED": "0",
    }
    common = ["--block", "--node-ip-address=127.0.0.1", "--num-cpus=1"]
    nodes = [
        subprocess.Popen(
            [ray, "start", "--head", f"--port={port}", "--include-dashboard=false", *common],
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
    ]
    try:
        address = f"127.0.0.1:{port}"
        _wait_for_nodes(ray, address, env, 1)
        nodes.append(
            subprocess.Popen(
                [ray, "start", f"--address={address}", *common],
                env=env,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
            )
        )
        _wait_for_nodes(ray, address, env, 2)
        out = tmp_path / "cluster"
        ray_args = ["--backend", "ray", "--address", address]
        done = subprocess.run(
            [sys.executable, "-m", "eval", "run", *GRID, "--out", str(out), *ray_args],
            cwd=ROOT,
            env=env,
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert done.returncode == 0, done.stderr[-2000:]
        assert "(Ray, 2 slots)" in done.stdout  # one CPU on each node
        assert _files(out) == reference
    finally:
        for node in reversed(nodes):
            node.send_signal(signal.SIGTERM)  # `ray start --block` stops its node's processes
        for node in nodes:
            node.wait(timeout=60)


def _wait_for_nodes(ray: Path, address: str, env: dict[str, str], n: int) -> None:
    deadline = time.monotonic() + 90
    while time.monotonic() < deadline:
        status = subprocess.run(
            [ray, "status", f"--address={address}"], env=env, capture_output=True, text=True
        )
        if status.returncode == 0 and status.stdout.count(" node_") >= n:
            return
        time.sleep(1)
    pytest.fail(f"the loopback cluster at {address} did not show {n} nodes within 90 s")


def test_a_run_that_fails_before_any_unit_leaves_no_journal(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    rollout_module = sys.modules["eval.rollout"]  # `eval.rollout` is also the function's name

    def broken(work: object) -> list:
        raise RuntimeError("a unit failed")

    monkeypatch.setattr(rollout_module, "_run_task", broken)
    out = tmp_path / "run"
    with pytest.raises(RuntimeError, match="a unit failed"):
        main(["run", *GRID, "--out", str(out), "--workers", "1"])
    assert not any(tmp_path.iterdir())  # neither the output folder nor its journal
