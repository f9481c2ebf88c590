"""Scale-out's rows in ``make bench``: evaluation throughput on each backend, in this process.

The grid is the issue's: 4 policies (pn, mpn, gsmpn, ppo) x every scenario x 100 seeds, each
episode reduced to its summed reward in the process that ran it (as a tuning search does), so
the figure is the backends' and not the step logs'. Each rate is set against the same grid run
in this process just before (``(l)``), and Ray's start-up is reported on its own: a command that
starts a local Ray pays it once. The scheduling overhead per task is the wall time per unit of
``execute`` over units that do nothing, on a pool and on Ray. The pool is started afresh for the
grid (its start is part of the grid's rate, as in a command's first batch) and kept for the
empty units (:func:`execution.shutdown_pools`), whose figure is then the scheduling alone.
"""

from __future__ import annotations

import operator
import time

from eval.rollout import rollout
from execution import Backend, execute, shutdown_pools

__all__ = ["bench_scale"]

POLICIES = ("pn", "mpn", "gsmpn", "ppo")
#: Seeds per (policy, scenario), full and quick.
SEEDS = {False: 100, True: 10}
#: Units of the overhead measurement, full and quick.
EMPTY_UNITS = {False: 2000, True: 200}


#: An episode's summed reward, computed where the episode ran (a picklable reducer).
episode_reward = operator.attrgetter("total_reward")


def _grid_rate(backend: Backend, seeds: int) -> tuple[float, list[float]]:
    from follow_env.tasks import get_task

    scenarios = get_task("person_follow").variants()
    started = time.perf_counter()
    got = rollout(list(POLICIES), scenarios, range(seeds), backend=backend, reduce=episode_reward)
    return len(got) / (time.perf_counter() - started), got


def _overhead_ms(backend: Backend, units: int) -> float:
    started = time.perf_counter()
    execute(operator.neg, range(units), backend)
    return 1000.0 * (time.perf_counter() - started) / units


def bench_scale(quick: bool) -> list[tuple[str, float, str]]:
    """Episodes/s of the grid in this process, on a 2-process pool and on a local Ray (its
    start-up apart), and the milliseconds of scheduling per unit; the results must agree."""
    try:
        import ray
    except ImportError:
        return [("scale-out", float("nan"), "Ray not installed: pip install -e '.[ray]'")]
    seeds = SEEDS[quick]
    here, base = _grid_rate(Backend("local", workers=1), seeds)
    shutdown_pools()  # a pool kept by an earlier section would hide the start
    pool, on_pool = _grid_rate(Backend("local", workers=2), seeds)
    units = EMPTY_UNITS[quick]
    # Right after the grid, so that its pool is still kept (POOL_IDLE_S) however long Ray takes.
    pool_ms = _overhead_ms(Backend("local", workers=2), units)
    ours = not ray.is_initialized()
    started = time.perf_counter()
    Backend("ray").slots()  # starts a local Ray with this machine's CPUs (unless one runs)
    startup = time.perf_counter() - started
    on_ray_rate, on_ray = _grid_rate(Backend("ray"), seeds)
    if not base == on_pool == on_ray:
        raise AssertionError("the backends gave different episodes for the same grid")
    n = len(base)
    rows = [
        (f"(l) {n} episodes, this process", here, "1.00x (l)"),
        (f"{n} episodes, pool of 2", pool, f"{pool / here:.2f}x (l)"),
        (f"{n} episodes, local Ray", on_ray_rate, f"{on_ray_rate / here:.2f}x (l)"),
        ("local Ray start-up (s)", startup, "once per command"),
    ]
    rows.append(("pool, per empty unit (ms)", pool_ms, "the grid's pool, kept"))
    rows.append(("Ray, per empty unit (ms)", _overhead_ms(Backend("ray"), units), ""))
    if ours:
        ray.shutdown()
    return rows
