"""How the execution layer fails: a unit's exception that cannot be pickled, an error or Ctrl-C
while units run, workers that die, a caller that dies, a Ray already connected elsewhere, and
settings refused before anything runs."""

from __future__ import annotations

import multiprocessing
import os
import pickle
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

import execution.backend
import execution.on_ray
from execution import Backend, BackendUnavailableError, execute, shutdown_pools
from execution.backend import UnitError, WorkerLostError

ROOT = Path(__file__).resolve().parents[2]


# -- a unit's exception that cannot be pickled ---------------------------------------------------


class TwoArgError(Exception):
    """Its ``args`` are not its ``__init__``'s: pickles, but does not unpickle."""

    def __init__(self, code: int, detail: str) -> None:
        super().__init__(f"code {code}: {detail}")


class LockedError(Exception):
    """Does not pickle at all."""

    def __init__(self, message: str) -> None:
        super().__init__(message)
        self.lock = threading.Lock()


@pytest.mark.parametrize(
    ("kind", "name", "message"),
    [("two", "TwoArgError", "code 7: bad unit"), ("lock", "LockedError", "lock inside")],
)
def test_an_exception_that_cannot_be_pickled_reaches_the_caller_and_is_not_retried(
    tmp_path: Path, kind: str, name: str, message: str
) -> None:
    units = [(str(tmp_path), kind, u) for u in range(3)]
    with pytest.raises(UnitError) as raised:
        execute(_raise_unpicklable, units, Backend("local", workers=2, max_retries=2))
    error = raised.value
    assert error.type_name.endswith(f".{name}")
    assert error.message == message
    assert f"{name}: {message}" in str(error)
    assert "_raise_unpicklable" in error.traceback_text  # where it was raised, in the worker
    # the unit's own error, not a lost worker: run once
    assert (tmp_path / "ran_1").read_text() == "x"


def test_a_unit_error_survives_pickling() -> None:
    error = UnitError("pkg.E", "7: bad", "Traceback ...")
    copy = pickle.loads(pickle.dumps(error))
    assert (copy.type_name, copy.message, copy.traceback_text, str(copy)) == (
        "pkg.E",
        "7: bad",
        "Traceback ...",
        str(error),
    )


# -- an error or Ctrl-C ends the pool's workers at once -----------------------------------------


@pytest.mark.parametrize("how", ["a unit's error", "Ctrl-C"])
def test_after_an_error_or_ctrl_c_the_pools_workers_are_ended_at_once(
    tmp_path: Path, how: str
) -> None:
    shutdown_pools()  # so that the only workers alive are this call's

    def interrupt(i: int, result: int) -> None:  # Ctrl-C reaching the caller as a result comes
        raise KeyboardInterrupt

    expected = RuntimeError if how == "a unit's error" else KeyboardInterrupt
    units = [(str(tmp_path), u, how == "a unit's error") for u in range(4)]
    started = time.monotonic()
    with pytest.raises(expected):
        execute(_fail_or_sleep, units, Backend("local", workers=2), on_result=interrupt)
    busy = int((tmp_path / "pid_1").read_text())  # the worker running the 30-s unit 1
    assert time.monotonic() - started < 15
    # ended and reaped, not left to finish its unit (the command would wait 30 s to exit)
    assert busy not in {p.pid for p in multiprocessing.active_children()}
    assert not execution.backend._POOLS


def test_a_pools_workers_exit_when_their_caller_is_killed(tmp_path: Path) -> None:
    # The caller is killed (SIGKILL: no cleanup) while its workers run 30-s units.
    script = tmp_path / "caller.py"
    script.write_text(
        "import os, sys, time\n"
        "from pathlib import Path\n"
        "from execution import Backend, execute\n"
        "def unit(u):\n"
        "    Path(sys.argv[1], f'pid_{u}').write_text(str(os.getpid()))\n"
        "    time.sleep(30)\n"
        "if __name__ == '__main__':\n"
        "    execute(unit, [0, 1], Backend(workers=2))\n"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    # Not capture_output: the orphaned workers would hold the pipes open.
    caller = subprocess.Popen([sys.executable, str(script), str(tmp_path)], env=env)
    workers: list[int] = []
    try:
        deadline = time.monotonic() + 20.0
        while len(workers) < 2:  # both units running
            assert time.monotonic() < deadline, "the units did not start"
            time.sleep(0.05)
            workers = [int(p.read_text() or 0) for p in tmp_path.glob("pid_*")]
            workers = [pid for pid in workers if pid]
        caller.kill()
        caller.wait(10)
        deadline = time.monotonic() + 5.0
        while any(_running(pid) for pid in workers):
            assert time.monotonic() < deadline, "the workers outlived their caller"
            time.sleep(0.1)
    finally:
        caller.kill()  # the processes this test started, if left running
        caller.wait(10)
        for pid in workers:
            if _running(pid):
                os.kill(pid, signal.SIGKILL)


def _running(pid: int) -> bool:
    """Whether process ``pid`` exists and is not a zombie (an exited child not yet reaped)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state != "Z"


# -- worker deaths count per unit ---------------------------------------------------------------


def test_retries_count_per_unit_not_per_run(tmp_path: Path) -> None:
    # Three units each kill their worker once: three deaths in the run, one per unit.
    units = [(str(tmp_path), u, u < 3) for u in range(4)]
    got = execute(_die_first_time, units, Backend("local", workers=2, max_retries=1))
    assert got == [0, 1, 2, 3]


def test_a_unit_that_keeps_killing_its_worker_is_named(tmp_path: Path) -> None:
    units = [(str(tmp_path), u, u == 2) for u in range(3)]
    with pytest.raises(WorkerLostError, match=r"unit 2\b.*max_retries=1"):
        execute(_die_always, units, Backend("local", workers=2, max_retries=1))
    assert (tmp_path / "ran_2").read_text() == "xx"  # run once, and retried once


# -- a pool backend uses its pool, even for one unit --------------------------------------------


def test_one_unit_on_a_pool_backend_runs_in_the_pool(tmp_path: Path) -> None:
    two = Backend("local", workers=2, max_retries=0)
    assert execute(os.getpid, [], two) == []
    [pid] = execute(_pid, [0], two)
    assert pid != os.getpid()
    # a worker dies, not this process; and the unit's worker deaths are counted
    with pytest.raises(WorkerLostError, match="unit 0"):
        execute(_die_always, [(str(tmp_path), 0, True)], two)


# -- Ray: a cluster named while Ray is already connected elsewhere ------------------------------


class _FakeRay:
    """Ray initialised in this process, connected to the cluster at 127.0.0.1:6379."""

    def is_initialized(self) -> bool:
        return True

    def get_runtime_context(self) -> Any:
        return SimpleNamespace(gcs_address="127.0.0.1:6379")

    def cluster_resources(self) -> dict[str, float]:
        return {"CPU": 2.0}

    util = SimpleNamespace(get_node_ip_address=lambda: "127.0.0.1")


def test_a_cluster_named_while_ray_is_connected_elsewhere_is_refused(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(execution.on_ray, "_import_ray", _FakeRay)
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    with pytest.raises(BackendUnavailableError, match=r"127\.0\.0\.1:1 .*already initialised"):
        Backend("ray", address="127.0.0.1:1").slots()
    with pytest.raises(BackendUnavailableError, match="already initialised"):
        Backend("ray", address="ray://127.0.0.1:10001").slots()
    monkeypatch.setenv("RAY_ADDRESS", "127.0.0.1:6380")
    with pytest.raises(BackendUnavailableError, match=r"127\.0\.0\.1:6380"):
        Backend("ray").slots()
    # the connected cluster, by another name of this machine, or no particular cluster
    monkeypatch.delenv("RAY_ADDRESS")
    for address in ("127.0.0.1:6379", "localhost:6379", "auto", "local", None):
        assert Backend("ray", address=address).slots() == 2


@pytest.mark.slow
def test_on_ray_an_unpicklable_exception_and_a_cluster_mismatch_are_reported(
    local_ray: Any, tmp_path: Path
) -> None:
    units = [(str(tmp_path), "two", u) for u in range(3)]
    with pytest.raises(UnitError, match="code 7: bad unit") as raised:
        execute(_raise_unpicklable, units, Backend("ray"))
    assert raised.value.type_name.endswith(".TwoArgError")
    with pytest.raises(BackendUnavailableError, match="already initialised"):
        execute(_pid, [0], Backend("ray", address="127.0.0.1:1"))
    connected = local_ray.get_runtime_context().gcs_address
    assert len(execute(_pid, [0, 1], Backend("ray", address=connected))) == 2


# -- settings refused before anything runs ------------------------------------------------------


@pytest.mark.parametrize(
    "address",
    ["nohost", "host:port", ":6379", "ray://", "auto ", " auto", "localhost:99999", "h:0", "",
     "ray://h", "a b:1", "::1:6379", 6379],
)  # fmt: skip
def test_a_malformed_ray_address_is_refused_at_once_naming_it(address: object) -> None:
    with pytest.raises(ValueError, match=r"address=.*not allowed.*HOST:PORT"):
        Backend("ray", address=address)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    "address",
    ["auto", "local", "127.0.0.1:6379", "headnode:6379", "ray://headnode:10001", "[::1]:6379"],
)
def test_a_well_formed_ray_address_is_accepted(address: str) -> None:
    assert Backend("ray", address=address).address == address


def test_numpy_integers_are_accepted_and_stored_as_int() -> None:
    backend = Backend(workers=np.int64(2), cpus_per_task=np.int32(1), max_retries=np.uint8(0))
    assert (backend.workers, backend.cpus_per_task, backend.max_retries) == (2, 1, 0)
    assert {type(v) for v in (backend.workers, backend.cpus_per_task, backend.max_retries)} == {int}
    with pytest.raises(ValueError, match="workers"):
        Backend(workers=np.int64(0))
    with pytest.raises(ValueError, match="workers"):
        Backend(workers=np.bool_(True))


# Unit functions must be importable by a worker: pytest imports this module as
# tests.execution.test_failures from the project's root, and so do spawned workers and Ray's.
def _raise_unpicklable(unit: tuple[str, str, int]) -> int:
    folder, kind, u = unit
    with open(Path(folder) / f"ran_{u}", "a") as attempts:
        attempts.write("x")
    if u == 1:
        raise TwoArgError(7, "bad unit") if kind == "two" else LockedError("lock inside")
    return u


def _fail_or_sleep(unit: tuple[str, int, bool]) -> int:
    """Unit 0 fails (or returns) once unit 1 has started; the others sleep 30 s."""
    folder, u, fail = unit
    (Path(folder) / f"pid_{u}").write_text(str(os.getpid()))
    if u != 0:
        time.sleep(30)
        return u
    deadline = time.monotonic() + 15
    while not (Path(folder) / "pid_1").exists() and time.monotonic() < deadline:
        time.sleep(0.02)
    if fail:
        raise RuntimeError("unit 0 failed")
    return u


def _die_first_time(unit: tuple[str, int, bool]) -> int:
    folder, u, die = unit
    marker = Path(folder) / f"died_{u}"
    if die and not marker.exists():
        marker.touch()
        os._exit(3)
    time.sleep(0.05)
    return u


def _die_always(unit: tuple[str, int, bool]) -> int:
    folder, u, die = unit
    with open(Path(folder) / f"ran_{u}", "a") as attempts:
        attempts.write("x")
    if die:
        os._exit(3)
    time.sleep(0.05)
    return u


def _pid(unit: object) -> int:
    return os.getpid()
