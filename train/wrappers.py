"""VecEnv wrappers between the batched env and PPO, and a VecEnv of several scenarios.

Each wrapper is an SB3 ``VecEnvWrapper``, listed by name under ``vec_env_wrapper`` in
``train/configs/ppo.yaml`` (so rl-zoo3 can build the same stack). All but the reward shaping are
thin wrappers of the agent's own feature pipeline (:mod:`policies.learned.features`), which the
policy runs at inference: one implementation, so the agent sees the same thing in both.
Innermost first:

- :class:`VecRescaleAction`: the agent acts in ``[-1, 1]``, mapped linearly onto SI speeds. PPO
  explores with one standard deviation for both outputs, so the range should be the useful one:
  ``w_max_radps`` 2 rad/s covers every turn rate the tuned laws command in any scenario (at most
  1.5 rad/s), where the platform's 7.4 rad/s would make most of the agent's range and most of
  its exploration spin the person out of view.
- :class:`VecShapedReward`: the training reward: the env's, floored and shifted so that no way
  of ending an episode early pays (a fresh agent otherwise learns to lose the person on
  purpose), minus penalties on command changes (smoothness) and on the observed offset.
  Training-only: the policy leaves it out, and every evaluation scores the env's own reward.
- :class:`VecJumpGate`: holds the last detection when the reading jumps further in a step than
  a person can walk (a bystander taking the person's place), so that it reads as stale.
- :class:`VecObservationAge`: appends how long the observation has been held (the perception
  repeats its last values while the detector sees nothing), so the agent can tell a fresh
  offset from a stale one.
- :class:`VecLawHint`: appends a guidance law's command on the observation, which
  ``VecIncrementalAction`` with ``prior_index`` can track (residual learning on a law).
- :class:`VecScaleObservation`: fixed scaling that keeps signed entries centred on 0 (needed by
  the mirror-symmetric policy, :mod:`train.mirror`).
- :class:`VecIncrementalAction`: the agent changes the command by at most a set step, and sees
  the command in force: smooth by construction, and the missing robot state (its own speed
  command) becomes part of the observation; ``held_floor`` keeps it from backing up while the
  detection is held. The observation ``[distance_m, offset_px]`` alone is
  not Markov (a frame of detector latency, held values, unobserved robot speed); the config's
  ``frame_stack`` adds the recent history on top.
- :class:`VecStackFrames`: that history as a wrapper of its own, listed last, which can start
  an episode's stack with its first observation repeated instead of ``VecFrameStack``'s zeros.

:class:`ConcatVecEnv` joins several VecEnvs, here one batched core per scenario (a core runs one
scenario for all its lanes), into one VecEnv whose lanes are the sub-envs' lanes in order.
``seed(s)`` gives lane ``j`` of the whole the seed ``s + j``, as for one VecEnv.

The action is the platform's, of any width (:func:`env_action_names` reads its entries' names
from the env): every wrapper keeps the names, and every per-action parameter (``max_change``,
``rate_weights``, the rescaling's limits) has one value per entry, in the platform's order.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, ClassVar

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper
from stable_baselines3.common.vec_env.base_vec_env import VecEnvObs, VecEnvStepReturn

from follow_env.sim.checks import check_number
from policies.learned.features import (
    Box,
    FrameStack,
    IncrementalAction,
    JumpGate,
    LawHint,
    ObservationAge,
    RescaleAction,
    ScaleObservation,
    agent_to_si,
)
from train.feature_wrapper import FeatureWrapper
from train.vecenvs import ConcatVecEnv, env_action_names, env_platform

__all__ = [
    "ConcatVecEnv",
    "VecIncrementalAction",
    "VecJumpGate",
    "VecLawHint",
    "VecObservationAge",
    "VecRescaleAction",
    "VecScaleObservation",
    "VecShapedReward",
    "VecStackFrames",
    "agent_to_si",
    "env_action_names",
    "env_platform",
]

# agent_to_si is re-exported: it lives with the features; ConcatVecEnv and the two readers of
# an env's platform with the VecEnvs (train.vecenvs).


class VecRescaleAction(FeatureWrapper):
    """:class:`policies.learned.features.RescaleAction`: the agent acts in ``[-1, 1]``, mapped
    onto SI speeds (``v_max_mps`` for the entries in m/s, ``w_max_radps`` for those in rad/s,
    each a number or one per such entry: the agent's range, at most the env's;
    ``reverse_max_mps``: a smaller backward speed on ``v_mps``)."""

    feature_class = RescaleAction


class VecObservationAge(FeatureWrapper):
    """:class:`policies.learned.features.ObservationAge`: appends how long the observation has
    been held (``max_age_steps``)."""

    feature_class = ObservationAge


class VecJumpGate(FeatureWrapper):
    """:class:`policies.learned.gate.JumpGate`: holds the last detection when the reading jumps
    further in a step than the person can walk (``max_jump_m``, ``max_jump_px``)."""

    feature_class = JumpGate


class VecLawHint(FeatureWrapper):
    """:class:`policies.learned.hint.LawHint`: appends a guidance law's command on the
    observation (``law``), in the agent's action units (``units``)."""

    feature_class = LawHint


class VecScaleObservation(FeatureWrapper):
    """:class:`policies.learned.features.ScaleObservation`: ``obs * scale``."""

    feature_class = ScaleObservation


class VecIncrementalAction(FeatureWrapper):
    """:class:`policies.learned.incremental.IncrementalAction`: the agent changes the command by at
    most ``max_change`` a step and sees the command in force."""

    feature_class = IncrementalAction


class VecStackFrames(FeatureWrapper):
    """:class:`policies.learned.features.FrameStack`: the last ``n_stack`` observations side
    by side, with ``pad: first`` the episode's first observation repeated before it (not
    ``VecFrameStack``'s zeros, which read as a person moving away fast). List it last (the
    outermost wrapper) in place of ``frame_stack``; with ``normalize: {norm_obs: true}`` the
    statistics are then those of the stacked frames."""

    feature_class = FrameStack


class VecShapedReward(VecEnvWrapper):
    """Training-only reward: ``max(r - far, reward_floor) + alive_bonus - rate terms``.

    The env's reward is meant for scoring a controller; these changes make it learnable:

    - ``reward_floor``: a step of the env's reward goes down to about -2 (alive 1, distance
      error capped at 1 m, offset up to 1, lost 1), and an episode in which the person is lost
      ends after 3 s. A fresh agent, which cannot follow yet, learns the cheapest exit: lose
      the person at once. Clipping a step's reward from below makes "far behind" no worse than
      "lost"; the step that ends an episode by termination is not clipped, so a collision
      keeps its full -50. (With the env's distance term capped at 1 m, a step 2 m behind
      is worth as little as one 10 m behind: ``far_weight`` below gives the gradient back.)
    - ``alive_bonus``: a constant per step. With the floor at -1 and the bonus at 1 every step is
      worth at least 0, so no exit (lost, collision) is ever better than going on; following
      well is worth about 1.8 a step.
    - ``sum_k rate_weights[k] |da_k|``: ``da`` is the change of the (clipped) action since the
      previous step, entry by entry, in the units of the wrapped action space (``[-1, 1]``
      above :class:`VecRescaleAction`); the first step of an episode compares with 0 (the robot
      starts at rest). ``v_rate_weight`` and ``w_rate_weight`` name the weights of the entries
      ``v_mps`` and ``w_radps`` (every platform has them; any other entry weighs 0); or give
      ``rate_weights``, one per action entry (the mecanum base's ``[v_mps, vy_mps, w_radps]``).
      The env's own reward charges 0.02 per m/s² of acceleration, a few hundredths of its
      distance and offset terms, which leaves the agent little reason to be
      smooth; the evaluation's StdAccel asks for exactly that.
    - ``far_weight``: the env's distance term is capped at 1 m of error (so that, scored, a
      person far away costs no more than a lost one), which leaves a trainee that has fallen
      more than 2 m behind no reason to catch up: measured, PPO with this project's settings
      reached held-out returns of +50 after 200 k steps before the cap and stayed below -40
      to 300 k steps after it. ``far_weight`` charges each metre of the observed distance's
      error beyond ``far_from_m`` (the cap) before the floor, as the env's term did before it
      was capped: the step's reward is ``r - far_weight * max(|d - target_distance_m| -
      far_from_m, 0) ** far_power`` (``d <= 0``, no reading yet: nothing), on the episode's
      last step from its terminal observation. ``far_power`` 2 charges the squared error, as
      the evaluation's RMS distance error does: a large lag (a person walking on while the
      robot slows in a detection gap) then costs more than a small steady offset (resting
      0.25 m too close after the person stops).
    - ``far_source`` and ``offset_source``: what the distance and offset terms measure, the
      ``observation`` (default) or the ``truth`` of the target (the env's info
      ``true_distance_m`` and ``true_offset_px``, which the wrapper asks the env to include:
      follow_env's SB3 adapter's :meth:`~follow_env.sim.sb3.TaskSB3VecEnv.include_info`). The
      observation is whoever the detector picked: when it picks a bystander 4 m away, a
      charge on the observed distance pays the agent to chase them (in ``crowd`` it did, and
      drove into the person it followed, who stood 1 m in front of it). The truth is known in
      simulation only, and only the reward reads it: the agent still sees the observation.
      (Measured, it did not stop those collisions: docs/learned/study.md, "Tried on top of
      ppo_fast.yaml".)
    - ``blind_speed_weight``: charges the forward speed command (``max(v, 0)`` in the units of
      the wrapped action: above :class:`VecRescaleAction`, 1 at full speed) on each step whose
      frame has no detection (the env's info ``detected``, which the wrapper asks the env to
      include, as for the truth). The laws stop when the person disappears (and lose them); an
      agent that drives on towards where they were runs into the wall they walked behind
      (``occlusion``). The charge is meant to teach it to slow down while it sees nothing; it
      comes after the floor, so a large weight makes standing still the cheapest course.
      (Measured, docs/learned/study.md, "Tried on top of ppo_fast.yaml": at 1 the agent backed
      away while blind and cut the corner when the person reappeared; at 3 it never set off.)
    - ``blind_reverse_weight``: the same charge on the backward speed command (``max(-v, 0)``)
      on steps without a detection. An agent that reads the depth ahead learnt to back away
      fast when something near comes between it and the person (the column of ``occlusion``, a
      pillar of ``random_world``): it then sees round it, but the person, who was walking round
      it at 1 m, is 2 m away, and in ``random_world`` it lost them (traced: 0.9 m/s backwards
      for 2 s). The laws, which go on at the last command, stay near.
    - ``clearance_weight``: charges coming near a wall, ``clearance_weight * max(clearance_m -
      c, 0) / clearance_m`` a step, where ``c`` is the robot footprint's true clearance to the
      nearest wall (the env's info ``wall_clearance_m``, included as for the truth; a
      collision at ``c <= 0`` ends the episode with the env's own penalty). The collision
      penalty alone is one sparse charge at the end; a wall approached is charged on every step
      before it, which tells the agent which of its paths cut a corner the person walked
      around. The agent still sees only the person: it can learn where walls tend to be from
      how the person moves, not see them. (Measured: at 2, wall collisions fell from 4 to 3 in
      240 episodes; at 5 the agent kept off walls by falling back and lost the person more.)
    - ``bystander_weight``: the same charge as ``clearance_weight`` for the nearest bystander,
      ``bystander_weight * max(bystander_m - c, 0) / bystander_m`` a step, ``c`` the footprint's
      true clearance to that person's body (the env's info ``bystander_clearance_m``, inf
      without bystanders). In ``crossing`` a stranger passes between the robot and the
      person it follows: a robot close behind the person touches them (the shipped agent in 2
      of 20 episodes), the law that falls furthest back none. The agent sees only the person
      it follows: it can learn that a stranger is near from how that observation jumps, not
      see where. (Measured: at 2 within 0.5 m and at 4 within 1 m, bystander collisions did
      not fall: docs/learned/study.md, "Tried on top of ppo_fast.yaml".)
    - ``near_weight``: charges being nearer than the following distance once more, on top of
      ``far_weight`` (the same distance, the same source, before the floor): ``near_weight *
      max(target_distance_m - d, 0)``. An agent charged alike on both sides overshoots when the
      person stops (it came to 0.76 m and backed off); a charge that is steeper on the near
      side makes closing in dearer than lagging. (Measured: at 2 and 4 the overshoot stayed.)
    - ``headway_s``: a following distance that grows with the robot's speed, ``target_distance_m
      + headway_s * max(v, 0)`` for ``far_weight`` and ``near_weight``, ``v`` the robot's own
      forward speed (the env's info ``robot_v_mps``, included as for the truth; a real robot
      has it from its wheels): the time gap of adaptive cruise control. A person walking
      beside a robot at 1 m leaves its image with one sideways step (``zigzag``), and agents
      trained to follow 1.1 m behind lost fewer; a robot standing near a person who walks
      round it (``occlusion``) or stops (``stop_and_go``) then pays for the extra 0.1 m. The
      env's own distance term keeps its ``reward.target_distance_m``.

    Put a ``VecMonitor`` below this wrapper to log the env's own episode returns.

    :param venv: a VecEnv with a ``Box`` action space whose infos mark truncation with
        ``TimeLimit.truncated`` (SB3's convention, as the PersonFollow adapter does).
    :param reward_floor: lower clip of a step's env reward, except on terminations; None: none.
    :param alive_bonus: added to every step's reward.
    :param v_rate_weight: weight on ``|dv|`` [reward per agent unit], >= 0.
    :param w_rate_weight: weight on ``|dw|`` [reward per agent unit], >= 0.
    :param rate_weights: one weight per action entry [reward per agent unit], each >= 0;
        instead of ``v_rate_weight`` / ``w_rate_weight``.
    :param offset_weight: weight on ``min(|observed offset| / (width / 2), 1)``, >= 0.
    :param far_weight: weight on the observed distance error beyond ``far_from_m`` [reward
        per m per step], >= 0; 0: none.
    :param far_from_m: the distance error the charge starts at [m] (the env's cap, 1 m), >= 0.
    :param far_power: the power of the error beyond ``far_from_m`` that is charged, in [1, 3]
        (1: the error in m; 2: its square in m²).
    :param target_distance_m: the following distance [m] (the env's 1 m), >= 0.
    :param far_source: ``observation`` or ``truth``: the distance ``far_weight`` charges.
    :param offset_source: ``observation`` or ``truth``: the offset ``offset_weight`` charges.
    :param blind_speed_weight: weight on the forward speed command on steps without a detection
        [reward per agent unit per step], >= 0; 0: none.
    :param blind_reverse_weight: weight on the backward speed command on steps without a
        detection [reward per agent unit per step], >= 0; 0: none.
    :param clearance_weight: weight on the wall clearance's shortfall below ``clearance_m``, as
        a share of it [reward per step at contact], >= 0; 0: none.
    :param clearance_m: the wall clearance below which the charge starts [m], > 0.
    :param bystander_weight: weight on the bystander clearance's shortfall below
        ``bystander_m``, as a share of it [reward per step at contact], >= 0; 0: none.
    :param bystander_m: the bystander clearance below which that charge starts [m], > 0.
    :param near_weight: weight on the distance's shortfall below ``target_distance_m``, on top
        of ``far_weight``'s charge [reward per m per step], >= 0; 0: none.
    :param headway_s: the following distance's growth with the robot's forward speed [s]
        (m per m/s), >= 0; 0: a fixed ``target_distance_m``.
    """

    #: Changes rewards only: the agent's pipeline leaves it out at inference
    #: (:meth:`policies.learned.features.Pipeline.view_entries`).
    training_only = True

    #: What a term may measure, and the info key of the truth for each term.
    SOURCES = ("observation", "truth")
    TRUTH_KEYS: ClassVar[dict[str, str]] = {
        "far_source": "true_distance_m",
        "offset_source": "true_offset_px",
    }
    #: The info key each weighted term, and ``headway_s``, reads (the wrapper asks the env to
    #: include it).
    WEIGHT_KEYS: ClassVar[dict[str, str]] = {
        "blind_speed_weight": "detected",
        "blind_reverse_weight": "detected",
        "clearance_weight": "wall_clearance_m",
        "bystander_weight": "bystander_clearance_m",
        "headway_s": "robot_v_mps",
    }

    def __init__(
        self,
        venv: VecEnv,
        reward_floor: float | None = None,
        alive_bonus: float = 0.0,
        v_rate_weight: float = 0.0,
        w_rate_weight: float = 0.0,
        offset_weight: float = 0.0,
        rate_weights: Sequence[float] | None = None,
        far_weight: float = 0.0,
        far_from_m: float = 1.0,
        far_power: float = 1.0,
        target_distance_m: float = 1.0,
        far_source: str = "observation",
        offset_source: str = "observation",
        blind_speed_weight: float = 0.0,
        clearance_weight: float = 0.0,
        clearance_m: float = 0.3,
        blind_reverse_weight: float = 0.0,
        near_weight: float = 0.0,
        bystander_weight: float = 0.0,
        bystander_m: float = 0.5,
        headway_s: float = 0.0,
    ) -> None:
        for name, value in (
            ("alive_bonus", alive_bonus),
            ("v_rate_weight", v_rate_weight),
            ("w_rate_weight", w_rate_weight),
            ("offset_weight", offset_weight),
            ("reward_floor", reward_floor),
            ("far_weight", far_weight),
            ("far_from_m", far_from_m),
            ("target_distance_m", target_distance_m),
            ("blind_speed_weight", blind_speed_weight),
            ("blind_reverse_weight", blind_reverse_weight),
            ("clearance_weight", clearance_weight),
            ("near_weight", near_weight),
            ("bystander_weight", bystander_weight),
            ("headway_s", headway_s),
        ):
            lo = 0.0 if name.endswith(("weight", "_m", "_s")) else None
            check_number(f"VecShapedReward.{name}", value, lo, optional=name == "reward_floor")
        for name, value in (("clearance_m", clearance_m), ("bystander_m", bystander_m)):
            check_number(f"VecShapedReward.{name}", value, 0.0, lo_open=True)
        if headway_s and not (far_weight or near_weight):
            raise ValueError(
                f"VecShapedReward.headway_s={headway_s!r} moves the distance far_weight and "
                "near_weight charge: give one of them"
            )
        check_number("VecShapedReward.far_power", far_power, 1.0, 3.0)
        sources = {"far_source": far_source, "offset_source": offset_source}
        for name, value in sources.items():
            if value not in self.SOURCES:
                raise ValueError(
                    f"VecShapedReward.{name}={value!r} is out of range: must be one of "
                    f"{', '.join(self.SOURCES)}"
                )
        truthful = [name for name, value in sources.items() if value == "truth"]
        needs = [f"{name}=truth" for name in truthful]
        keys = [self.TRUTH_KEYS[name] for name in truthful]
        weights = {
            "blind_speed_weight": blind_speed_weight,
            "blind_reverse_weight": blind_reverse_weight,
            "clearance_weight": clearance_weight,
            "bystander_weight": bystander_weight,
            "headway_s": headway_s,
        }
        for name, key in self.WEIGHT_KEYS.items():
            if weights[name]:
                needs.append(name)
                keys.append(key)
        keys = list(dict.fromkeys(keys))  # the blind terms share one key
        if keys:
            try:  # every lane's env (the adapter keeps one set of keys for all its lanes)
                venv.env_method("include_info", keys)
                kept = all(set(keys) <= set(have) for have in venv.get_attr("info_keys"))
            except AttributeError:
                kept = False
            if not kept:
                raise ValueError(
                    f"VecShapedReward: {' and '.join(needs)} needs an env whose infos can carry "
                    f"{', '.join(keys)} (follow_env's SB3 adapter: include_info)"
                )
        act_box = venv.action_space
        if not isinstance(act_box, spaces.Box) or len(act_box.shape) != 1:
            raise ValueError(f"VecShapedReward needs a flat Box action space, got {act_box}")
        names = Box(act_box.low, act_box.high, env_action_names(venv)).entry_names()
        self.rate_weights = self._weights(names, v_rate_weight, w_rate_weight, rate_weights)
        super().__init__(venv)
        self.reward_floor = -np.inf if reward_floor is None else float(reward_floor)
        self.alive_bonus = float(alive_bonus)
        self.offset_weight = float(offset_weight)
        self.far_weight = float(far_weight)
        self.far_from_m = float(far_from_m)
        self.far_power = float(far_power)
        self.target_distance_m = float(target_distance_m)
        self.far_source = far_source
        self.offset_source = offset_source
        self.blind_speed_weight = float(blind_speed_weight)
        self.blind_reverse_weight = float(blind_reverse_weight)
        self.clearance_weight = float(clearance_weight)
        self.clearance_m = float(clearance_m)
        self.near_weight = float(near_weight)
        self.bystander_weight = float(bystander_weight)
        self.bystander_m = float(bystander_m)
        self.headway_s = float(headway_s)
        self._v_entry = names.index("v_mps") if "v_mps" in names else None
        for name in ("blind_speed_weight", "blind_reverse_weight"):
            if getattr(self, name) and self._v_entry is None:
                raise ValueError(
                    f"VecShapedReward.{name}: the env's action [{', '.join(names)}] has no v_mps"
                )
        self._half_width_px = float(venv.observation_space.high[1]) + 1.0
        self._low, self._high = act_box.low, act_box.high
        self._prev = np.zeros((venv.num_envs, len(names)))
        self._change = np.zeros((venv.num_envs, len(names)))

    @staticmethod
    def _weights(
        names: tuple[str, ...], v_weight: float, w_weight: float, given: Sequence[float] | None
    ) -> np.ndarray:
        """One rate weight per action entry, from ``rate_weights`` or the named two."""
        if given is None:
            weights = np.zeros(len(names))
            for field, entry, value in (
                ("v_rate_weight", "v_mps", v_weight),
                ("w_rate_weight", "w_radps", w_weight),
            ):
                if value and entry not in names:
                    raise ValueError(
                        f"VecShapedReward.{field}: the env's action [{', '.join(names)}] has no "
                        f"{entry}; give rate_weights"
                    )
                if entry in names:
                    weights[names.index(entry)] = value
            return weights
        if v_weight or w_weight:
            raise ValueError(
                "VecShapedReward: give rate_weights or v_rate_weight / w_rate_weight, not both"
            )
        rule = f"{len(names)} numbers >= 0, one per action entry [{', '.join(names)}]"
        if not isinstance(given, list | tuple) or len(given) != len(names):
            raise ValueError(
                f"VecShapedReward.rate_weights={given!r} is out of range: must be {rule}"
            )
        for k, value in enumerate(given):
            check_number(f"VecShapedReward.rate_weights[{k}] ({names[k]})", value, 0.0)
        return np.asarray(given, dtype=np.float64)

    def reset(self) -> VecEnvObs:
        self._prev[:] = 0.0
        return self.venv.reset()

    def _truth(self, source: str, infos: list[dict[str, Any]]) -> np.ndarray:
        """Each lane's true value for ``source`` (``far_source`` or ``offset_source``)."""
        return self._info(self.TRUTH_KEYS[source], infos)

    @staticmethod
    def _info(key: str, infos: list[dict[str, Any]]) -> np.ndarray:
        """Each lane's info ``key`` as floats, the final state's where an episode ended (the
        adapter's ``include_info``, which the constructor asked for)."""
        try:
            return np.array([info[key] for info in infos], dtype=np.float64)
        except KeyError:
            raise ValueError(
                f"VecShapedReward: the env's infos carry no {key!r} (include_info was not kept "
                "by the env below)"
            ) from None

    def _far(self, obs: np.ndarray, dones: np.ndarray, infos: list[dict[str, Any]]) -> np.ndarray:
        """The ``far_weight`` and ``near_weight`` charge of each lane's step, from the distance
        it reached: the truth's, or the observation's (the terminal one where an episode ended;
        rows ``[distance_m, offset_px, ...]``; no reading yet, ``d <= 0``: nothing)."""
        if self.far_source == "truth":
            d = self._truth("far_source", infos)
        else:
            d = np.array(obs, dtype=np.float64)[:, 0]
            for i in np.flatnonzero(dones):  # the episode's own last observation, not the reset's
                if "terminal_observation" in infos[i]:
                    d[i] = float(np.asarray(infos[i]["terminal_observation"])[0])
        target = self.target_distance_m
        if self.headway_s:
            v = self._info(self.WEIGHT_KEYS["headway_s"], infos)
            target = target + self.headway_s * np.maximum(v, 0.0)
        excess = np.maximum(np.abs(d - target) - self.far_from_m, 0.0)
        near = np.maximum(target - d, 0.0)
        charge = self.far_weight * excess**self.far_power + self.near_weight * near
        return np.where(d > 0.0, charge, 0.0)

    def step_async(self, actions: np.ndarray) -> None:
        a = np.asarray(actions, dtype=np.float64).reshape(self._prev.shape)
        a = np.clip(a, self._low, self._high)
        self._change = np.abs(a - self._prev)
        self._prev = a
        self.venv.step_async(actions)

    def step_wait(self) -> VecEnvStepReturn:
        obs, rewards, dones, infos = self.venv.step_wait()
        truncated = np.array([info.get("TimeLimit.truncated", False) for info in infos])
        terminated = np.asarray(dones, dtype=bool) & ~truncated
        r = np.asarray(rewards, dtype=np.float64)
        if self.far_weight or self.near_weight:
            r = r - self._far(obs, dones, infos)
        shaped = np.where(terminated, r, np.maximum(r, self.reward_floor))
        shaped += self.alive_bonus - self._change @ self.rate_weights
        if self.offset_weight:
            if self.offset_source == "truth":
                offset = self._truth("offset_source", infos)
            else:  # the observation the agent sees next (the reset's after an episode's end)
                offset = np.asarray(obs, dtype=np.float64)[:, 1]
            shaped -= self.offset_weight * np.minimum(np.abs(offset) / self._half_width_px, 1.0)
        if self.blind_speed_weight or self.blind_reverse_weight:
            blind = self._info(self.WEIGHT_KEYS["blind_speed_weight"], infos) == 0.0
            v = self._prev[:, self._v_entry]
            charge = self.blind_speed_weight * np.maximum(v, 0.0)
            charge += self.blind_reverse_weight * np.maximum(-v, 0.0)
            shaped -= np.where(blind, charge, 0.0)
        for name, weight, within in (
            ("clearance_weight", self.clearance_weight, self.clearance_m),
            ("bystander_weight", self.bystander_weight, self.bystander_m),
        ):
            if weight:
                c = self._info(self.WEIGHT_KEYS[name], infos)
                short = np.clip(within - c, 0.0, within) / within
                shaped -= weight * short
        self._prev[dones] = 0.0
        return obs, shaped.astype(np.float32), dones, infos
