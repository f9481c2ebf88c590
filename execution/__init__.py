"""One execution layer for evaluation, tuning and training: work units on a backend.

A *work unit* is a picklable argument for a module-level function: (policy, scenario, config,
seed chunk) for an evaluation, (trial parameters, seed chunk) for a tuning trial, (training
config, seed) for a training run. :func:`execute` runs ``fn(unit)`` for every unit on a
:class:`Backend` and returns the results in the units' order, whichever finished first:

- ``local``: in this process (``workers=1``) or a pool of spawned processes (``workers`` of
  2 or more: a pool, however few the units);
- ``ray``: tasks on ``ray.init()``: a local Ray sized to this machine when no cluster is named,
  ``address=`` (``--address``) or ``RAY_ADDRESS`` for a cluster, checked before ``ray.init``
  so that an address no Ray answers at fails in one message rather than minutes of Ray's
  retries (:mod:`execution.ray_address`). Ray is an optional extra (from a clone: ``pip
  install -e '.[ray]' --config-settings editable_mode=compat``).

Every task pins its numba, torch and OpenMP threads to the CPUs it was given
(:func:`pin_threads`), so two tasks on one machine never oversubscribe it. A worker that dies
mid-task is retried (a new Ray task; a rebuilt pool locally), up to ``max_retries`` times per
unit, each death logged as one warning line (logger ``execution``) naming the unit; then
:class:`WorkerLostError` names it. Units are pure functions of their arguments, so a retried
unit returns exactly what the first attempt would have. An exception a unit raises is never
retried: it reaches the caller as raised, the worker's traceback chained to it as its
``__cause__`` (:class:`RemoteTraceback`) and the unit and host in a note
(:func:`unit_origin`), or as a :class:`UnitError` naming it if it cannot be pickled back from
its worker. A Ray result is copied out of Ray's shared-memory object store as it arrives.
After an error or Ctrl-C a pool's workers are ended at once (not left to finish their units),
and a pool's workers exit if the process that started them dies. A local pool is kept for the
next call with the same workers (a spawned process takes about 2 s to start) until it has been
idle for ``execution.backend.POOL_IDLE_S`` (60 s), the process exits or :func:`shutdown_pools`
is called; one that failed is not kept. A local Ray that :func:`execute` started is kept and
stopped alike, and started again for a call that wants another number of CPUs; a Ray the
caller started, or a cluster, is used as it is and never stopped.

This package imports nothing else of the project: every layer above may use it.
"""

from execution.backend import (
    BACKENDS,
    WORKERS_LOST,
    Backend,
    BackendUnavailableError,
    RemoteTraceback,
    UnitError,
    WorkerLostError,
    backend_from_args,
    error_line,
    execute,
    pin_threads,
    shutdown_pools,
    unit_origin,
)

__all__ = [
    "BACKENDS",
    "WORKERS_LOST",
    "Backend",
    "BackendUnavailableError",
    "RemoteTraceback",
    "UnitError",
    "WorkerLostError",
    "backend_from_args",
    "error_line",
    "execute",
    "pin_threads",
    "shutdown_pools",
    "unit_origin",
]
