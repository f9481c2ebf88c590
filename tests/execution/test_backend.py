"""The execution layer: every backend returns the units' results in order, the same ones."""

from __future__ import annotations

import multiprocessing
import operator
import os
import signal
import socket
import sys
import time
from pathlib import Path

import pytest

import execution.backend
from execution import (
    Backend,
    BackendUnavailableError,
    backend_from_args,
    execute,
    pin_threads,
    shutdown_pools,
)
from execution.backend import WorkerLostError, _check_reachable

UNITS = list(range(12))
EXPECTED = [operator.neg(u) for u in UNITS]


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("kind", "slurm"),
        ("workers", 0),
        ("workers", 1.5),
        ("cpus_per_task", 0),
        ("max_retries", -1),
    ],
)
def test_a_bad_backend_field_is_refused_by_name(field: str, value: object) -> None:
    with pytest.raises(ValueError, match=field if field != "kind" else "backend"):
        Backend(**{field: value})


def test_an_address_is_only_for_ray() -> None:
    with pytest.raises(ValueError, match="address"):
        Backend("local", address="127.0.0.1:6379")


def test_in_process_results_come_in_unit_order() -> None:
    assert execute(operator.neg, UNITS) == EXPECTED


def test_a_pool_returns_the_same_results_in_unit_order_from_pinned_workers() -> None:
    seen: list[int] = []
    got = execute(
        _neg_and_threads,
        UNITS,
        Backend("local", workers=2, cpus_per_task=1),
        on_result=lambda i, r: seen.append(i),
    )
    assert [r[0] for r in got] == EXPECTED
    assert sorted(seen) == list(range(len(UNITS)))
    # numba's and torch's threads and OpenMP's, in the worker: the CPUs it was given
    assert {r[1:] for r in got} == {(1, 1, "1")}


def test_done_units_are_not_run_again() -> None:
    ran: list[int] = []
    done = {0: "kept", 5: "kept"}
    got = execute(operator.neg, UNITS, done=done, on_result=lambda i, r: ran.append(i))
    assert got[0] == got[5] == "kept"
    assert got[1] == -1
    assert set(ran) == set(range(len(UNITS))) - {0, 5}


def test_a_units_own_error_reaches_the_caller_unchanged() -> None:
    with pytest.raises(TypeError, match="bad operand"):
        execute(operator.neg, [1, "x"], Backend("local", workers=2))


def test_a_pool_is_kept_for_the_next_call_with_the_same_workers() -> None:
    shutdown_pools()
    two = Backend("local", workers=2)
    first = set(execute(_slow_pid, range(16), two))
    assert len(first) == 2  # both workers took units
    assert set(execute(_slow_pid, range(8), two)) == first  # the same processes: no new start
    pinned = set(execute(_slow_pid, range(8), Backend("local", workers=2, cpus_per_task=2)))
    assert pinned.isdisjoint(first)  # other CPUs per worker: a pool of its own
    assert {p.pid for p in multiprocessing.active_children()} >= first | pinned
    shutdown_pools()
    assert not {p.pid for p in multiprocessing.active_children()} & (first | pinned)


def test_a_kept_pool_stops_when_idle_and_a_call_in_time_keeps_it(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    shutdown_pools()
    monkeypatch.setattr(execution.backend, "POOL_IDLE_S", 1.5)
    two = Backend("local", workers=2)
    first = set(execute(_slow_pid, range(8), two))
    time.sleep(0.5)  # within the idle time: the same workers, and the wait starts again
    assert set(execute(_slow_pid, range(8), two)) == first
    time.sleep(1.0)  # 1.0 s after the last call: still there
    assert {p.pid for p in multiprocessing.active_children()} >= first
    deadline = time.monotonic() + 10.0
    while {p.pid for p in multiprocessing.active_children()} & first:
        assert time.monotonic() < deadline, "the idle pool's workers did not exit"
        time.sleep(0.1)
    assert not execution.backend._POOLS
    # the next call starts a new pool
    assert set(execute(_slow_pid, range(8), two)).isdisjoint(first)
    shutdown_pools()


def test_a_pool_that_failed_is_not_kept() -> None:
    two = Backend("local", workers=2)
    before = set(execute(_slow_pid, range(8), two))
    with pytest.raises(TypeError, match="bad operand"):
        execute(operator.neg, [1, "x", 3, 4], two)
    assert set(execute(_slow_pid, range(8), two)).isdisjoint(before)


def test_a_pool_worker_killed_mid_run_is_replaced_and_the_results_are_unchanged() -> None:
    shutdown_pools()  # so that the only workers alive are this run's
    killed: list[int] = []

    def kill_a_worker(i: int, result: int) -> None:
        if not killed:  # after the first unit: the other worker is busy or about to be
            victim = multiprocessing.active_children()[0]
            os.kill(victim.pid, signal.SIGKILL)
            killed.append(victim.pid)

    units = list(range(40))
    got = execute(
        _slow_neg, units, Backend("local", workers=2, max_retries=2), on_result=kill_a_worker
    )
    assert killed
    assert got == [-u for u in units]


def test_workers_that_keep_dying_give_up_after_the_retries() -> None:
    with pytest.raises(WorkerLostError, match="max_retries=1"):
        execute(os._exit, [3, 3], Backend("local", workers=2, max_retries=1))


def test_pinning_limits_numba_and_torch_in_this_process() -> None:
    import numba
    import torch

    before = (numba.get_num_threads(), torch.get_num_threads(), os.environ.get("OMP_NUM_THREADS"))
    try:
        pin_threads(1)
        assert (numba.get_num_threads(), torch.get_num_threads()) == (1, 1)
    finally:
        numba.set_num_threads(before[0])
        torch.set_num_threads(before[1])
        if before[2] is None:
            os.environ.pop("OMP_NUM_THREADS", None)
        else:
            os.environ["OMP_NUM_THREADS"] = before[2]


def test_ray_without_ray_installed_says_how_to_install_it(monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray now raises ImportError
    # the README's install of a clone, not a release from PyPI
    hint = r"pip install -e '\.\[ray\]' --config-settings editable_mode=compat"
    with pytest.raises(BackendUnavailableError, match=hint):
        backend_from_args("ray")


@pytest.mark.slow
def test_ray_returns_what_the_local_backend_returns(local_ray) -> None:
    assert execute(operator.neg, UNITS, Backend("ray")) == EXPECTED
    with pytest.raises(TypeError, match="bad operand"):
        execute(operator.neg, [1, "x"], Backend("ray"))
    assert Backend("ray").slots() == 2  # the session's Ray has 2 CPUs


@pytest.mark.slow
def test_ray_retries_a_unit_whose_worker_was_killed(local_ray) -> None:
    killed = []

    def kill_a_busy_worker(i: int, result: int) -> None:
        if not killed:
            pids = _busy_ray_workers()
            if pids:
                os.kill(pids[0], signal.SIGKILL)
                killed.append(pids[0])

    units = list(range(40))
    got = execute(_slow_neg, units, Backend("ray", max_retries=3), on_result=kill_a_busy_worker)
    assert killed, "no Ray worker was seen running a unit"
    assert got == [-u for u in units]


def _busy_ray_workers() -> list[int]:
    """Ray worker processes running a unit now (Ray titles them ``ray::<task>``)."""
    pids = []
    for proc in Path("/proc").iterdir():
        try:
            title = (proc / "cmdline").read_bytes().split(b"\0")[0]
        except OSError:
            continue
        if title.startswith(b"ray::_call"):
            pids.append(int(proc.name))
    return pids


# Unit functions must be importable by a worker: library functions, or these from this module,
# which pytest imports as tests.execution.test_backend from the project's root (a spawned pool
# worker and a local Ray worker import it by that name from the same folder).
def _slow_neg(x: int) -> int:
    import time

    time.sleep(0.05)
    return -x


def _slow_pid(x: int) -> int:
    _slow_neg(x)
    return os.getpid()


def _neg_and_threads(x: int) -> tuple[int, int, int, str | None]:
    import numba
    import torch

    threads = numba.get_num_threads(), torch.get_num_threads(), os.environ.get("OMP_NUM_THREADS")
    return (-x, *threads)


# The checks ray.init is preceded by for a named cluster (a Ray already running in this process,
# the session's, would be used instead of connecting, so they are called directly).
def test_an_unreachable_cluster_fails_at_once_naming_it() -> None:
    with socket.socket() as s:  # a port nothing listens at: bound, never listening
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
        where = f"cannot reach the Ray cluster at 127.0.0.1:{port}"
        with pytest.raises(BackendUnavailableError, match=where):
            _check_reachable(f"127.0.0.1:{port}")


def test_a_malformed_cluster_address_is_refused() -> None:
    for address in ("headnode", "headnode:\u00b2", "headnode:\u0663"):  # "²" broke int()
        with pytest.raises(BackendUnavailableError, match="not a Ray cluster address"):
            _check_reachable(address)
    _check_reachable("local")  # Ray's own word for a new instance: nothing to try


def test_a_unit_finished_as_the_pool_breaks_is_neither_lost_nor_run_twice(monkeypatch) -> None:
    """The pool breaks (a worker died) between a unit's result and the next submission: the
    finished unit is handed out once, and the retry runs only the others."""
    from concurrent.futures import Future
    from concurrent.futures.process import BrokenProcessPool

    import execution.backend as backend_module

    class BreaksOnSubmit:  # runs units at once; its 5th submission finds the pool broken
        submitted = 0

        def submit(self, fn, *args):
            BreaksOnSubmit.submitted += 1
            if BreaksOnSubmit.submitted == 5:
                raise BrokenProcessPool("a worker died")
            future: Future = Future()
            future.set_result(fn(*args))
            return future

        def shutdown(self, wait: bool = True, cancel_futures: bool = False) -> None:
            pass

    monkeypatch.setattr(backend_module, "_pool", lambda workers, cpus: BreaksOnSubmit())
    monkeypatch.setattr(backend_module, "_keep", lambda key, pool: None)
    monkeypatch.setattr(backend_module, "_drop", lambda key, pool: None)
    handed: list[int] = []
    got = execute(
        operator.neg,
        list(range(10)),
        Backend("local", workers=2, max_retries=1),
        on_result=lambda i, result: handed.append(i),
    )
    assert got == [-u for u in range(10)]
    assert sorted(handed) == list(range(10))  # each unit once


@pytest.mark.slow
def test_a_ray_unit_finished_as_the_next_submission_fails_is_handed_on(
    local_ray, monkeypatch
) -> None:
    """The cluster is lost between a unit's result and the next submission: the finished unit
    still reaches the caller (a run's journal keeps it) before the error."""
    from execution.backend import _IN_FLIGHT_PER_SLOT

    first = _IN_FLIGHT_PER_SLOT * Backend("ray").slots()  # submitted before any result
    real = local_ray.remote

    class LostOnSubmit:  # the real task, until the submission after the first ones
        def __init__(self, task) -> None:
            self.task, self.submitted = task, 0

        def options(self, **options):
            self.task = self.task.options(**options)
            return self

        def remote(self, *args):
            self.submitted += 1
            if self.submitted > first:
                raise ConnectionError("the cluster is gone")
            return self.task.remote(*args)

    monkeypatch.setattr(local_ray, "remote", lambda fn: LostOnSubmit(real(fn)))
    handed: list[int] = []
    with pytest.raises(ConnectionError, match="the cluster is gone"):
        execute(
            operator.neg, list(range(10)), Backend("ray"), on_result=lambda i, r: handed.append(i)
        )
    assert len(handed) == 1  # the unit whose result came before the failed submission
