"""The agent's command steps, numpy only: it changes the command by at most a set step a frame
and sees the command in force (:class:`IncrementalAction`, a step of the agent's view,
:mod:`policies.learned.features`).

Smooth by construction: the commanded acceleration is bounded, and PPO's exploration noise
becomes a random walk of the command. While the detection is held (the perception repeats its
last values) the command can be held to a floor (no backing up blind) and chosen entries kept
as they were (the turn kept behind an occluder). Given a prior command in the view (a guidance
law's, :class:`~policies.learned.hint.LawHint`), an action of zero tracks it.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from follow_env.sim.checks import check_number, is_integer
from policies.learned.boxes import Box, per_entry
from policies.learned.feature import Feature, append_entries

__all__ = ["IncrementalAction"]


class IncrementalAction(Feature):
    """The agent changes the command by at most ``max_change`` a step; observation gets the
    command.

    The inner action is ``u_t = clip(u_{t-1} + max_change * clip(a_t, -1, 1))`` (clipped to the
    inner action box), from ``u = 0`` (the robot at rest) at every episode start. The observation
    is ``[obs..., u_{t-1}...]``, the command in force when the observation was taken. The
    commanded acceleration can never exceed ``max_change / dt``, and PPO's exploration noise
    becomes a random walk of the command instead of a new random command every 0.1 s.

    :param max_change: the largest change per step of each action entry, in inner units (one
        per entry of the platform's action, in its order).
    :param reading_index: the observation entry holding the distance, or None. While it is <= 0
        (no distance reading yet) the command does not change, so the robot stays at rest until
        it first measures the person, as the reference robot and every guidance law do.
    :param brake_change: the largest change per step towards rest, one per entry (inner
        units), or None: ``max_change`` both ways. Given, an action against the command's sign
        takes ``|u|`` down by up to ``brake_change * |a|``, stopping at rest
        (docs/learned/study.md, "Tried on top of ppo_fast.yaml": it did not stop the overshoot
        at stops).
    :param held_index: the observation entry that is > 0 while the detection is held (not
        fresh), :class:`ObservationAge`'s age; or None. Needs ``held_floor``.
    :param held_floor: while the detection is held, the lowest command of each entry (inner
        units; None: the box's), one per entry. ``[0, null]``: no backing up while the person
        is not seen, the robot's camera looking forward. A command below the floor when the
        detection goes stale rises to it by ``max_change`` a step, so the acceleration bound
        holds (README, "No backing up blind").
    :param held_keep: while the detection is held, the entries whose command stays as it was
        (one bool per entry), or None: none. ``[false, true]`` keeps turning at the rate the
        robot turned when the person was last seen, as the laws do on a stale offset: a
        person walking round the robot behind something is still in view when they come out.
        Needs ``held_index``; the floor, if given, still applies to the others.
    :param ahead_index: with ``held_keep``, the observation entry holding the reading ahead, or
        None: keep in every gap. Given, the entries are kept only in a gap in which the reading
        ahead has read nearer than the held distance (entry ``reading_index``) by more than
        ``behind_margin_m``: something came between the robot and the person, who is then
        taken to walk on as they did. A gap with nothing nearer (the detector missed the person)
        leaves the agent free to turn back towards where it last saw them.
    :param behind_margin_m: how much nearer than the held distance the reading ahead must read
        (m, > 0; None: 0.2). Needs ``ahead_index``.
    :param prior_index: the first of the observation entries holding a prior command, one per
        action entry in this step's units (:class:`~policies.learned.hint.LawHint`'s law), or
        None. Given, the step is ``max_change * clip(a + prior_gain * (prior - u) /
        max_change, -1, 1)``: an action of zero tracks the prior command at up to the bound,
        and the agent learns where to depart from it.
    :param prior_gain: the share of the distance to the prior command closed a step (in
        (0, 1], within the bound; None: 1). Needs ``prior_index``.
    """

    def __init__(
        self,
        max_change: Sequence[float] = (0.1, 0.1),
        reading_index: int | None = None,
        brake_change: Sequence[float] | None = None,
        held_index: int | None = None,
        held_floor: Sequence[float | None] | None = None,
        held_keep: Sequence[bool] | None = None,
        ahead_index: int | None = None,
        behind_margin_m: float | None = None,
        prior_index: int | None = None,
        prior_gain: float | None = None,
    ) -> None:
        self.given = max_change
        self.reading_index = reading_index
        self.given_brake = brake_change
        self.held_index = held_index
        self.given_floor = held_floor
        self.given_keep = held_keep
        self.ahead_index = ahead_index
        self.behind_margin_m = behind_margin_m
        self.prior_index = prior_index
        self.prior_gain = prior_gain

    def bind(self, obs: Box, act: Box, n: int) -> tuple[Box, Box]:
        change = self._steps("max_change", self.given, act)
        brake = (
            None if self.given_brake is None else self._steps("brake_change", self.given_brake, act)
        )
        n_obs = obs.shape[0]
        for field in ("reading_index", "held_index", "ahead_index", "prior_index"):
            index = getattr(self, field)
            if index is not None and not (is_integer(index) and 0 <= index < n_obs):
                raise ValueError(
                    f"{self.owner}.{field}={index!r} is out of range: must be None or an "
                    f"observation index in [0, {n_obs - 1}]"
                )
        self.max_change = change
        self.brake_change = brake
        self._low = act.low.astype(np.float64)
        self._high = act.high.astype(np.float64)
        self._check_held_options()
        if self.prior_index is not None:
            last = self.prior_index + act.shape[0] - 1
            if last >= n_obs:
                raise ValueError(
                    f"{self.owner}.prior_index={self.prior_index!r} is out of range: the "
                    f"{act.shape[0]} prior entries must lie in [0, {n_obs - 1}]"
                )
            gain = 1.0 if self.prior_gain is None else self.prior_gain
            self.prior_gain = check_number(f"{self.owner}.prior_gain", gain, 0.0, 1.0, lo_open=True)
        elif self.prior_gain is not None:
            raise ValueError(
                f"{self.owner}.prior_gain={self.prior_gain!r}: needs prior_index (the prior "
                "command it tracks)"
            )
        self._prior = np.zeros((n, act.shape[0]))
        self._floor = self._held_floor(act)
        self._keep = self._held_keep(act)
        self._behind = np.zeros(n, dtype=bool)
        self._command = np.zeros((n, act.shape[0]))
        self._reading = np.ones(n, dtype=bool)
        self._held = np.zeros(n, dtype=bool)
        outer_obs = Box(np.concatenate([obs.low, act.low]), np.concatenate([obs.high, act.high]))
        return outer_obs, Box(-np.ones(act.shape), np.ones(act.shape), act.names)

    def _steps(self, field: str, given: Any, act: Box) -> np.ndarray:
        """``given`` as one positive step per action entry, or a ValueError naming ``field``."""
        may = "None or " if field == "brake_change" else ""
        return per_entry(f"{self.owner}.{field}", given, act, may)

    def _check_held_options(self) -> None:
        """The options that act while the detection is held go together: ``held_floor`` and
        ``held_keep`` need ``held_index`` (and it needs one of them); ``ahead_index`` needs
        ``held_keep`` and ``reading_index``, and a positive ``behind_margin_m``."""
        index = self.held_index
        held = {"held_floor": self.given_floor, "held_keep": self.given_keep}
        uses = [f"{name}={value!r}" for name, value in held.items() if value is not None]
        if uses and index is None:
            raise ValueError(f"{self.owner}.{' and '.join(uses)}: needs held_index")
        if index is not None and not uses:
            raise ValueError(
                f"{self.owner}.held_index={index!r} serves nothing: give held_floor or "
                "held_keep, or leave held_index out"
            )
        if self.ahead_index is not None:
            if self.given_keep is None or self.reading_index is None:
                raise ValueError(
                    f"{self.owner}.ahead_index={self.ahead_index!r}: needs held_keep and "
                    "reading_index"
                )
            margin = 0.2 if self.behind_margin_m is None else self.behind_margin_m
            self.behind_margin_m = check_number(
                f"{self.owner}.behind_margin_m", margin, 0.0, None, lo_open=True
            )
        elif self.behind_margin_m is not None:
            raise ValueError(
                f"{self.owner}.behind_margin_m={self.behind_margin_m!r}: needs ahead_index "
                "(the reading it compares)"
            )

    def _held_keep(self, act: Box) -> np.ndarray | None:
        """``held_keep`` as one bool per entry, or None."""
        given = self.given_keep
        if given is None:
            return None
        names = act.entry_names()
        ok = isinstance(given, list | tuple) and all(isinstance(b, bool) for b in given)
        if not ok or len(given) != len(names):
            raise ValueError(
                f"{self.owner}.held_keep={given!r} is out of range: must be {len(names)} "
                f"booleans, one per action entry [{', '.join(names)}]"
            )
        return np.array(given, dtype=bool)

    def _held_floor(self, act: Box) -> np.ndarray | None:
        """``held_floor`` as one lower bound per entry (the box's for null), or None."""
        given = self.given_floor
        if given is None:
            return None
        names = act.entry_names()
        if not isinstance(given, list | tuple) or len(given) != len(names):
            raise ValueError(
                f"{self.owner}.held_floor={given!r} is out of range: must be {len(names)} "
                f"entries, one per action entry [{', '.join(names)}] (a number or null)"
            )
        floor = act.low.astype(np.float64).copy()
        for k, value in enumerate(given):
            if value is not None:
                label = f"{self.owner}.held_floor[{k}] ({names[k]})"
                floor[k] = check_number(label, value, float(act.low[k]), float(act.high[k]))
        return floor

    def start(self, obs: np.ndarray) -> np.ndarray:
        self._command[:] = 0.0
        self._note_reading(obs)
        return self._join(obs, self._command)

    def act(self, action: np.ndarray) -> np.ndarray:
        a = np.clip(np.asarray(action, dtype=np.float64).reshape(self._command.shape), -1, 1)
        u = self._command
        if self.prior_index is not None:  # towards the prior command, the agent's on top
            a = np.clip(a + self.prior_gain * (self._prior - u) / self.max_change, -1.0, 1.0)
        a[~self._reading] = 0.0
        moved = u + self.max_change * a
        if self.brake_change is not None:  # towards rest: down by up to brake_change, to zero
            slowed = np.sign(u) * np.maximum(np.abs(u) - self.brake_change * np.abs(a), 0.0)
            moved = np.where(a * u < 0.0, slowed, moved)
        if self._floor is not None and self._held.any():
            # held: no lower than the floor, or than a command rising to it at the largest step
            low = np.minimum(self._floor, u + self.max_change)
            moved[self._held] = np.maximum(moved[self._held], low[self._held])
        if self._keep is not None and self._held.any():
            gap = self._held if self.ahead_index is None else self._behind  # held, behind
            kept = gap[:, None] & self._keep[None, :]
            moved[kept] = u[kept]
        self._command = np.clip(moved, self._low, self._high)
        return self._command.astype(np.float32)

    def observe(self, obs: np.ndarray, done: np.ndarray) -> np.ndarray:
        self._note_reading(obs)
        self._command[done] = 0.0
        return self._join(obs, self._command)

    def terminal(self, obs: np.ndarray, lane: int) -> np.ndarray:
        return self._join(obs, self._command[lane])

    def _note_reading(self, obs: np.ndarray) -> None:
        if self.prior_index is not None:
            k = self.prior_index
            self._prior = np.asarray(obs, dtype=np.float64)[:, k : k + self._command.shape[1]]
        if self.reading_index is not None:
            self._reading = np.asarray(obs)[:, self.reading_index] > 0
        if self.held_index is not None:
            self._held = np.asarray(obs)[:, self.held_index] > 0
        if self.ahead_index is not None:
            # latched for the rest of the gap: turning, the robot may leave the occluder's side
            rows = np.asarray(obs)
            nearer = rows[:, self.ahead_index] < rows[:, self.reading_index] - self.behind_margin_m
            self._behind = self._held & (self._behind | nearer)

    @staticmethod
    def _join(obs: np.ndarray, command: np.ndarray) -> np.ndarray:
        return append_entries(obs, command)
