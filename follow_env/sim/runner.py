"""The batched lane runner: N lanes of one (platform, task) pair, stepped by one kernel.

All state lives in a few arrays with one entry per lane: ``params`` and ``state`` are arrays of
records (:mod:`follow_env.sim.schema`) whose blocks are the platform's and the task's, plus the
robot's body and the episode's counters; ``world`` is the task's tuple of per-lane arrays (e.g.
people, paths, walls); ``keys`` are the lanes' random stream keys. One call of the pair's
compiled kernel (:mod:`follow_env.sim.compose`) advances every lane by one control step; from
:data:`PARALLEL_MIN_LANES` lanes on the lanes are split into one block per core, each stepped
on its own thread (the kernel releases the GIL). The single env is one lane; the vector env and
the SB3 adapter are the same runner with N lanes, so they cannot drift apart.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Protocol

import numpy as np

from follow_env.sim import compose
from follow_env.sim.body import BODY
from follow_env.sim.checks import out_of_range
from follow_env.sim.jit import compile_notice
from follow_env.sim.rng import LaneSeeds
from follow_env.sim.schema import Block, f8, i8
from follow_env.sim.streams import N_STREAMS

__all__ = ["EPISODE", "PARALLEL_MIN_LANES", "BatchedSim", "LaneView", "PlatformModel", "TaskModel"]

EPISODE = Block(
    "episode",
    "the episode's counters and this step's outcome, written by the task's kernel",
    [
        i8("step", "steps", "control steps taken"),
        f8("t", "s", "episode time"),
        f8("reward", "", "this step's reward"),
        f8("terminated", "", "1 when the episode ended in a terminal state"),
        f8("truncated", "", "1 when the episode was cut short"),
        i8("reason", "", "why the episode ended (the task's termination codes; 0: not ended)"),
    ],
)

PARALLEL_MIN_LANES = 256
"""From this many lanes on, the runner steps blocks of lanes on one thread per core."""


class PlatformModel(Protocol):
    """What the runner needs of a platform (``follow_env.platforms.base.Platform``)."""

    name: str
    module: str
    params: Block
    state: Block

    def randomize(
        self, params: np.ndarray, base: np.void, lanes: np.ndarray, cfg: Any, keys: np.ndarray
    ) -> None:
        """Per-episode draws into the lanes' platform parameter records."""


class TaskModel(Protocol):
    """What the runner needs of a task (see ``follow_env.tasks.person_follow.task``)."""

    name: str
    kernel_module: str
    params: Block
    state: Block

    def platform_of(self, cfg: Any) -> PlatformModel:
        """The platform the configuration names."""

    def check(self, cfg: Any) -> None:
        """Refuse a configuration the task cannot run (naming the field)."""

    def world(self, cfg: Any, num_lanes: int) -> tuple[np.ndarray, ...]:
        """The task's per-lane arrays, zeroed."""

    def prepare_reset(self, sim: BatchedSim, lanes: np.ndarray, keys: np.ndarray) -> np.ndarray:
        """Write the new episodes' world into ``sim`` (the lanes' state is zeroed); return the
        robots' start poses ``(len(lanes), 3)``."""


_DTYPES: dict[tuple[int, int], tuple[np.dtype, np.dtype]] = {}


def _composed_dtypes(platform: PlatformModel, task: TaskModel) -> tuple[np.dtype, np.dtype]:
    """The parameter and state record types of a (platform, task) pair, made once: numba's
    dispatcher recognises an argument's type quickly only by the very same dtype object (an
    equal but new one takes its slow path, about 6 us a call)."""
    key = (id(platform.params), id(task.params))
    if key not in _DTYPES:
        params = np.dtype(
            [("platform", platform.params.dtype), ("task", task.params.dtype)], align=True
        )
        state = np.dtype(
            [
                ("body", BODY.dtype),
                ("episode", EPISODE.dtype),
                ("platform", platform.state.dtype),
                ("task", task.state.dtype),
            ],
            align=True,
        )
        _DTYPES[key] = params, state
    return _DTYPES[key]


class LaneView:
    """One lane's live records: ``params``, ``state`` (numpy records) and ``world`` (the
    lane's entry of each world array). Reading them always shows the current step."""

    def __init__(self, sim: BatchedSim, lane: int) -> None:
        self.lane = lane
        self.cfg = sim.cfg
        self.params = sim.params[lane]
        self.state = sim.state[lane]
        self.world = tuple(w[lane] for w in sim.world)


class BatchedSim:
    """N lanes of the simulation, each running its own episode.

    :param task: the task model (its blocks, world arrays and resets).
    :param cfg: the configuration shared by all lanes (its ``platform`` names the platform).
    :param num_lanes: N.
    """

    def __init__(self, task: TaskModel, cfg: Any, num_lanes: int) -> None:
        if (
            isinstance(num_lanes, bool)
            or not isinstance(num_lanes, int | np.integer)
            or num_lanes < 1
        ):
            raise out_of_range("num_lanes", num_lanes, "an integer >= 1")
        num_lanes = int(num_lanes)
        self.task = task
        self.cfg = cfg
        self.n = num_lanes
        self.platform: Any = task.platform_of(cfg)
        task.check(cfg)
        self.params_dtype, self.state_dtype = _composed_dtypes(self.platform, task)
        self.base_params = np.zeros((), self.params_dtype)
        self.platform.params.fill(self.base_params["platform"], cfg)
        task.params.fill(self.base_params["task"], cfg)
        self.params = np.empty(num_lanes, self.params_dtype)
        self.params[:] = self.base_params
        self.state = np.zeros(num_lanes, self.state_dtype)
        self.world = task.world(cfg, num_lanes)
        # Every record is made of 8-byte words: these views (no copies) let readers gather many
        # fields of many lanes in one indexing operation (columns from schema.float_column).
        self.state_words = self.state.view(np.float64).reshape(num_lanes, -1)
        self._state_raw = self.state.view(np.uint64).reshape(num_lanes, -1)
        self._params_raw = self.params.view(np.uint64).reshape(num_lanes, -1)
        self._base_raw = self.base_params.reshape(1).view(np.uint64)
        self.state_ints = self.state.view(np.int64).reshape(num_lanes, -1)
        self.world_words = tuple(w.view(np.float64).reshape(num_lanes, -1) for w in self.world)
        ep = self.state_dtype.fields["episode"][1] // 8
        ep_fields = EPISODE.dtype.fields
        self._reward_col = ep + ep_fields["reward"][1] // 8
        self._end_cols = [ep + ep_fields[k][1] // 8 for k in ("terminated", "truncated")]
        self.keys = np.zeros((num_lanes, N_STREAMS), dtype=np.uint64)
        self.seeds = LaneSeeds(num_lanes)
        self._all = np.ones(num_lanes, dtype=np.bool_)
        kernels = compose.kernels(
            task.name, task.kernel_module, self.platform.name, self.platform.module
        )
        self._step_kernel, self._reset_kernel = kernels.step_lanes, kernels.reset_lanes
        compile_notice([self._step_kernel, self._reset_kernel])
        workers = min(os.cpu_count() or 1, max(1, num_lanes // (PARALLEL_MIN_LANES // 2)))
        self._pool: ThreadPoolExecutor | None = None
        self._blocks: list[tuple[int, int]] = []
        if num_lanes >= PARALLEL_MIN_LANES and workers > 1:
            edges = np.linspace(0, num_lanes, workers + 1).astype(int)
            self._blocks = list(zip(edges[:-1].tolist(), edges[1:].tolist(), strict=True))
            self._pool = ThreadPoolExecutor(workers - 1, thread_name_prefix="personfollow")

    # -- lanes ----------------------------------------------------------------------------------

    @property
    def body(self) -> np.ndarray:
        """Every lane's body record (pose, twist, measured speed)."""
        return self.state["body"]

    @property
    def episode(self) -> np.ndarray:
        """Every lane's episode record (step, time, reward, flags, reason)."""
        return self.state["episode"]

    def outcome(self, lane: int) -> tuple[float, bool, bool]:
        """Lane ``lane``'s last step: ``(reward, terminated, truncated)``."""
        words = self.state_words[lane]
        term, trunc = self._end_cols
        return float(words[self._reward_col]), bool(words[term] > 0.0), bool(words[trunc] > 0.0)

    def lane(self, i: int) -> LaneView:
        """A live view of lane ``i`` (for renderers and tests)."""
        return LaneView(self, i)

    def reset_lanes(self, lanes: np.ndarray, seeds: list[int | None] | None = None) -> None:
        """Start the next episode of each of ``lanes``.

        :param lanes: lane indices.
        :param seeds: new root seeds for these lanes (an int, or ``None`` for OS entropy,
            each); without it every lane goes on to its next episode (see
            :class:`~follow_env.sim.rng.LaneSeeds`).
        """
        lanes = np.asarray(lanes, dtype=np.int64)
        if seeds is not None:
            self.seeds.seed(lanes, list(seeds))
        keys = self.seeds.next_keys(lanes)
        self.keys[lanes] = keys
        # Raw 8-byte copies: the lanes' state zeroed, their parameters the configured ones.
        self._state_raw[lanes] = 0
        self._params_raw[lanes] = self._base_raw
        self.platform.randomize(
            self.params["platform"], self.base_params["platform"], lanes, self.cfg, keys
        )
        pose = self.task.prepare_reset(self, lanes, keys)
        self._reset_kernel(
            lanes,
            np.ascontiguousarray(pose, dtype=np.float64),
            self.params,
            self.state,
            self.world,
            self.keys,
        )

    def step(self, actions: np.ndarray, active: np.ndarray | None = None) -> None:
        """Advance the lanes by one control step; ``actions`` is (N, action size) float64;
        ``active`` (N,) bool selects the lanes to step (default: all)."""
        mask = self._all if active is None else active
        if self._pool is None:
            self._step_kernel(self.params, self.state, self.world, self.keys, actions, mask)
            return

        def block(lo: int, hi: int) -> None:
            self._step_kernel(
                self.params[lo:hi],
                self.state[lo:hi],
                tuple(w[lo:hi] for w in self.world),
                self.keys[lo:hi],
                actions[lo:hi],
                mask[lo:hi],
            )

        # One block of lanes per core; the kernel releases the GIL, and this thread takes the
        # first block itself rather than wait idle.
        jobs = [self._pool.submit(block, lo, hi) for lo, hi in self._blocks[1:]]
        block(*self._blocks[0])
        for job in jobs:
            job.result()

    # -- copies -----------------------------------------------------------------------------------

    def __getstate__(self) -> dict[str, Any]:
        """What a copy needs: the configuration and the lanes' records, not the views onto them.

        ``copy.deepcopy`` and pickle copy a numpy view as a separate array, so a copy of the
        raw attributes would step ``state`` while reading stale ``state_words`` (and reset
        through a ``_state_raw`` that no longer aliases ``state``); the kernels and the thread
        pool are rebuilt rather than copied.
        """
        return {
            "task": self.task,
            "cfg": self.cfg,
            "n": self.n,
            "params": self.params,
            "state": self.state,
            "world": self.world,
            "keys": self.keys,
            "seeds": self.seeds,
        }

    def __setstate__(self, saved: dict[str, Any]) -> None:
        """Rebuild the runner (views, kernels, pool) and copy the saved records into it."""
        self.__init__(saved["task"], saved["cfg"], saved["n"])  # type: ignore[misc]
        # Raw 8-byte copies: the saved records have the layout of this runner's, but may be
        # of an equal rather than the very same dtype object (see _composed_dtypes).
        self._params_raw[:] = saved["params"].view(np.uint64).reshape(self.n, -1)
        self._state_raw[:] = saved["state"].view(np.uint64).reshape(self.n, -1)
        for mine, theirs in zip(self.world, saved["world"], strict=True):
            mine.view(np.uint64)[...] = theirs.view(np.uint64)
        self.keys[:] = saved["keys"]
        self.seeds = saved["seeds"]

    def close(self) -> None:
        """Stop the worker threads (if any)."""
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None
