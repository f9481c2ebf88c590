"""What the execution layer tells its caller about work in other processes: a unit's exception
with the worker's traceback and where it was raised, a worker's death that was retried, the unit
whose worker kept dying; a Ray result owned by the caller, and the local Ray that the layer
starts, resized and stopped as a pool is."""

from __future__ import annotations

import logging
import os
import pickle
import signal
import socket
import subprocess
import sys
import time
import traceback
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

import execution.backend
import execution.on_ray
from execution import Backend, RemoteTraceback, execute, shutdown_pools, unit_origin
from execution.backend import WorkerLostError

ROOT = Path(__file__).resolve().parents[2]


# -- a unit's exception: the worker's traceback, and which unit raised it where ----------------


def test_a_pool_units_exception_names_the_unit_and_host_and_keeps_the_workers_frames() -> None:
    with pytest.raises(ValueError, match="bad seed 3") as raised:
        execute(_raise_for_3, range(5), Backend("local", workers=2), describe=lambda u: f"s{u}")
    error = raised.value
    where = unit_origin(error)
    assert where.startswith(f"work unit 3 (s3) on host {socket.gethostname()}, process ")
    assert f"(raised in {where})" in getattr(error, "__notes__", [])
    text = "".join(traceback.format_exception(error))
    assert "_helper_that_raises" in text  # a frame of the worker, in the cause
    assert unit_origin(ValueError("raised here")) == ""  # not from a worker: no origin


@pytest.mark.slow
def test_on_ray_a_units_exception_keeps_the_workers_traceback(local_ray: Any) -> None:
    with pytest.raises(ValueError, match="bad seed 3") as raised:
        execute(_raise_for_3, range(5), Backend("ray"))
    error = raised.value
    # chained as a pool chains it, not dropped (`from None` left only this module's frames)
    assert isinstance(error.__cause__, RemoteTraceback)
    text = "".join(traceback.format_exception(error))
    assert "_helper_that_raises" in text
    assert "\x1b[" not in text  # Ray's terminal colours taken out
    assert unit_origin(error).startswith("work unit 3 (3) on host ")


# -- a worker's death: one warning when retried, the unit named when it keeps dying -------------


def test_a_worker_death_that_is_retried_is_reported_once_naming_the_unit(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    units = [(str(tmp_path), u, u == 2) for u in range(4)]
    with caplog.at_level(logging.WARNING, logger="execution"):
        got = execute(
            _sigkill_first_time, units, Backend("local", workers=2), describe=lambda u: f"#{u[1]}"
        )
    assert got == [0, 1, 2, 3]
    [line] = [r.getMessage() for r in caplog.records if r.name == "execution"]
    assert "unit 2 (#2)" in line
    assert "SIGKILL" in line
    assert "out-of-memory" in line
    assert "retry 1 of max_retries=3" in line


def test_a_unit_that_keeps_killing_its_worker_is_named_in_the_callers_terms(tmp_path: Path) -> None:
    units = [(str(tmp_path), u, u == 1) for u in range(3)]
    with pytest.raises(WorkerLostError) as raised:
        execute(
            _sigkill_always,
            units,
            Backend("local", workers=2, max_retries=1),
            describe=lambda u: f"policy pn, seeds {u[1]}0-{u[1]}9",
        )
    error = raised.value
    assert (error.index, error.label, error.deaths) == (1, "(policy pn, seeds 10-19)", 2)
    assert str(error).startswith("unit 1 (policy pn, seeds 10-19): its worker process died 2 ")
    assert "killed by SIGKILL" in str(error)
    copy = pickle.loads(pickle.dumps(error))  # crosses processes as raised
    assert (str(copy), copy.index, copy.label) == (str(error), 1, error.label)


def test_by_default_a_unit_is_named_by_its_repr_cut_short(tmp_path: Path) -> None:
    long = ("pn", "straight", tuple(range(1000)), "x" * 500)
    with pytest.raises(WorkerLostError) as raised:
        execute(
            _sigkill_always, [(str(tmp_path), 0, True, long)], Backend(workers=2, max_retries=0)
        )
    label = raised.value.label
    assert ", 0, True, ('pn', 'straight', (0, 1, 2, 3, 4, 5, ...), 'xxx" in label
    assert "x" * 41 not in label
    assert len(label) <= 122  # in its parentheses


@pytest.mark.slow
def test_on_ray_a_death_is_retried_per_unit_and_reported(
    local_ray: Any, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    units = [(str(tmp_path), u, u == 2) for u in range(4)]
    with caplog.at_level(logging.WARNING, logger="execution"):
        assert execute(_sigkill_first_time, units, Backend("ray")) == [0, 1, 2, 3]
    [line] = [r.getMessage() for r in caplog.records if r.name == "execution"]
    assert line.startswith("warning: the Ray worker running unit 2 ((")
    assert "died with Ray's WorkerCrashedError" in line
    assert "retry 1 of max_retries=3" in line
    always = [(str(tmp_path), u, u == 1) for u in range(3)]
    with pytest.raises(WorkerLostError, match=r"unit 1 .* died 2 times \(max_retries=1"):
        execute(_sigkill_always, always, Backend("ray", max_retries=1))


# -- Ray's results are the caller's own ----------------------------------------------------------


@pytest.mark.slow
def test_ray_results_are_copied_out_of_rays_object_store(local_ray: Any) -> None:
    got = execute(_megabyte, range(3), Backend("ray"))
    # 1 MB each: kept in the shared-memory store, where ray.get maps them read-only and pinned
    assert all(a.flags.owndata and a.flags.writeable for a in got)
    assert [float(a[0]) for a in got] == [0.0, 1.0, 2.0]


# -- the local Ray this layer starts: restarted for other CPUs, stopped when idle ---------------


class _RayToStart:
    """A Ray module's surface, with no Ray running until ``init``."""

    def __init__(self) -> None:
        self.running: int | None = None  # CPUs of the running instance
        self.started = 0
        self.inits: list[dict[str, Any]] = []
        self.shutdowns = 0
        self.util = SimpleNamespace(get_node_ip_address=lambda: "127.0.0.1")

    def is_initialized(self) -> bool:
        return self.running is not None

    def init(self, **options: Any) -> None:
        self.inits.append(options)
        self.running = options.get("num_cpus", 8)
        self.started += 1

    def shutdown(self) -> None:
        self.shutdowns += 1
        self.running = None

    def get_runtime_context(self) -> Any:
        return SimpleNamespace(gcs_address=f"127.0.0.1:{6000 + self.started}")

    def cluster_resources(self) -> dict[str, float]:
        return {"CPU": float(self.running or 0)}

    # Tasks run at once, here: a reference is its result, and the CPUs it ran with.
    exceptions = SimpleNamespace(
        RayTaskError=type("RayTaskError", (Exception,), {}),
        **{
            name: type(name, (Exception,), {})
            for name in (
                "WorkerCrashedError",
                "NodeDiedError",
                "OutOfMemoryError",
                "ObjectLostError",
            )
        },
    )

    def remote(self, fn: Any) -> Any:
        ray = self

        class Task:
            def options(self, **options: Any) -> Task:
                return self

            def remote(self, *args: Any) -> Any:
                return (fn(*args), ray.running)

        return Task()

    def wait(self, refs: list[Any], num_returns: int) -> tuple[list[Any], list[Any]]:
        return refs[:num_returns], refs[num_returns:]

    def get(self, ref: Any) -> Any:
        return ref

    def cancel(self, ref: Any, force: bool) -> None:
        pass


@pytest.fixture
def fake_ray(monkeypatch: pytest.MonkeyPatch) -> _RayToStart:
    ray = _RayToStart()
    monkeypatch.setattr(execution.on_ray, "_import_ray", lambda: ray)
    monkeypatch.setitem(sys.modules, "ray", ray)  # what _shutdown_started imports
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    monkeypatch.setattr(execution.on_ray, "_STARTED", None, raising=False)
    yield ray
    shutdown_pools()  # the fake Ray this test's calls started, and its idle timer


def _cpus_of(backend: Backend) -> set[int]:
    """The CPUs of the Ray the units ran on (the fake's task results carry them)."""
    return {cpus for _, cpus in execute(abs, [-1, -2], backend)}


def test_a_local_ray_started_here_is_restarted_for_other_cpus(fake_ray: _RayToStart) -> None:
    assert _cpus_of(Backend("ray", workers=1)) == {1}
    assert _cpus_of(Backend("ray", workers=1)) == {1}  # the same CPUs: kept
    assert _cpus_of(Backend("ray", workers=2)) == {2}  # other CPUs: not silently run on 1
    assert [o["num_cpus"] for o in fake_ray.inits] == [1, 2]
    assert fake_ray.shutdowns == 1


def test_a_local_ray_started_here_stops_when_idle_or_at_shutdown_pools(
    fake_ray: _RayToStart, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(execution.backend, "POOL_IDLE_S", 0.2)
    assert _cpus_of(Backend("ray", workers=1)) == {1}
    assert fake_ray.is_initialized()
    deadline = time.monotonic() + 5
    while fake_ray.is_initialized():
        assert time.monotonic() < deadline, "the idle Ray was not shut down"
        time.sleep(0.05)
    monkeypatch.setattr(execution.backend, "POOL_IDLE_S", 60.0)
    Backend("ray").slots()  # started again (all CPUs); stopped at once by shutdown_pools
    shutdown_pools()
    assert (fake_ray.started, fake_ray.shutdowns) == (2, 2)


def test_a_ray_the_caller_started_is_never_shut_down(fake_ray: _RayToStart) -> None:
    fake_ray.init(num_cpus=4)  # the caller's, as a notebook's
    assert _cpus_of(Backend("ray", workers=1)) == {4}  # used as it is
    assert Backend("ray").slots() == 4
    shutdown_pools()
    assert fake_ray.is_initialized()
    assert fake_ray.shutdowns == 0


@pytest.mark.slow
def test_a_real_local_ray_is_resized_and_stopped(tmp_path: Path) -> None:
    # In a process of its own: this session's Ray (conftest's local_ray) would be used instead.
    script = tmp_path / "resize.py"
    script.write_text(
        "import os, ray\n"
        "from execution import Backend, execute, shutdown_pools\n"
        "execute(os.getpid, [], Backend('ray'))\n"  # no unit: no Ray started
        "assert not ray.is_initialized()\n"
        "execute(abs, [-1, -2], Backend('ray', workers=1))\n"
        "assert ray.cluster_resources()['CPU'] == 1\n"
        "execute(abs, [-1, -2], Backend('ray', workers=2))\n"
        "assert ray.cluster_resources()['CPU'] == 2\n"
        "shutdown_pools()\n"
        "assert not ray.is_initialized()\n"
        "print('ok')\n"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT), "RAY_USAGE_STATS_ENABLED": "0"}
    env.pop("RAY_ADDRESS", None)
    done = subprocess.run(
        [sys.executable, str(script)], env=env, capture_output=True, text=True, timeout=300
    )
    assert done.stdout.strip() == "ok", done.stderr[-3000:]


# Unit functions must be importable by a worker: pytest imports this module as
# tests.execution.test_reporting from the project's root, and so do spawned workers and Ray's.
def _helper_that_raises(u: int) -> int:
    if u == 3:
        raise ValueError(f"bad seed {u}")
    return u


def _raise_for_3(u: int) -> int:
    return _helper_that_raises(u)


def _sigkill_first_time(unit: tuple[str, int, bool]) -> int:
    """Unit ``u`` with ``die`` set kills its own worker (SIGKILL, as the OOM killer) once."""
    folder, u, die = unit
    marker = Path(folder) / f"died_{u}"
    if die and not marker.exists():
        marker.touch()
        os.kill(os.getpid(), signal.SIGKILL)
    return u


def _sigkill_always(unit: tuple[Any, ...]) -> int:
    _, u, die = unit[:3]
    if die:
        os.kill(os.getpid(), signal.SIGKILL)
    return u


def _megabyte(k: int) -> np.ndarray:
    return np.full(131_072, float(k))
