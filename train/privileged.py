"""The simulation's truth for the critic only: an asymmetric actor-critic.

The agent acts on what the robot perceives: a detection that can be a bystander's, held through
gaps, and a reading ahead that cannot tell a column from the person. Its value network needs no
such limit: it is used in training only, to judge the actor's steps, and the simulator knows the
truth. Given the truth, the critic can tell the states the actor cannot (the detector took a
bystander 4 m away while the person stands 0.7 m in front; a column hides the person who is still
1 m away), so a step is judged by where it really leads rather than by the average over every
state that looks alike, and the rare events that end episodes are credited where they happen
(Pinto et al., "Asymmetric Actor Critic for Image-Based Robot Learning", RSS 2018).

:class:`VecPrivilegedCritic`, listed last in a file's ``vec_env_wrapper``, appends the truth of
the state each step reached to the agent's view, from the env's infos (which it asks the SB3
adapter to include): :data:`PRIVILEGED`. The policy must read those entries in its critic only:
:class:`policies.learned.mirror.MirrorMlpPolicy` with ``privileged_signs`` (one sign per entry,
:data:`PRIVILEGED_SIGNS`) builds its actor on the entries before them. The wrapper is
training-only: the agent's pipeline leaves it out at inference, so the actor sees exactly the
view it acts on, on the robot as in evaluation.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper
from stable_baselines3.common.vec_env.base_vec_env import VecEnvObs, VecEnvStepReturn

from follow_env.sim.checks import check_number

__all__ = ["PRIVILEGED", "PRIVILEGED_SIGNS", "VecPrivilegedCritic"]

#: The critic's entries, in order: (name, the info key it is read from, its sign in a
#: left-right mirror). Offsets are in half image widths; clearances in m, capped at ``clip_m``.
PRIVILEGED: tuple[tuple[str, str, float], ...] = (
    ("true_distance_m", "true_distance_m", 1.0),
    ("true_offset", "true_offset_px", -1.0),
    ("in_frame", "in_frame", 1.0),
    ("other_person_detected", "detected_person", 1.0),
    ("nobody_detected", "detected_person", 1.0),
    ("wall_clearance_m", "wall_clearance_m", 1.0),
    ("bystander_clearance_m", "bystander_clearance_m", 1.0),
)

#: ``policy_kwargs.privileged_signs`` for :data:`PRIVILEGED`.
PRIVILEGED_SIGNS: list[float] = [sign for _, _, sign in PRIVILEGED]


class VecPrivilegedCritic(VecEnvWrapper):
    """Appends :data:`PRIVILEGED` to each observation, for the critic (module docstring).

    A step's entries describe the state it reached (an ended episode's final state in its
    ``terminal_observation``). The first observation of an episode, after a reset, gets the
    start every scenario shares: the person 1 m ahead, centred, in frame and detected, and the
    clearances at ``clip_m`` (the adapter reports the final state of an ended lane, not the
    new one's).

    :param venv: the agent's view (the wrapper goes last, after the frame stack), over
        follow_env's SB3 adapter, which can include the infos.
    :param clip_m: the clearances' cap [m], > 0; ``inf`` (no bystander) reads as the cap.
    :param half_width_px: the offset's unit [px], > 0: half the image width (320 px).
    :raises ValueError: for a bad parameter, or an env whose infos cannot carry the keys.
    """

    #: Changes what the critic sees only: the agent's pipeline leaves it out at inference.
    training_only = True
    KEYS: ClassVar[tuple[str, ...]] = tuple(dict.fromkeys(key for _, key, _ in PRIVILEGED))

    def __init__(self, venv: VecEnv, clip_m: float = 2.0, half_width_px: float = 320.0) -> None:
        check_number("VecPrivilegedCritic.clip_m", clip_m, 0.0, lo_open=True)
        check_number("VecPrivilegedCritic.half_width_px", half_width_px, 0.0, lo_open=True)
        try:
            venv.env_method("include_info", list(self.KEYS))
            kept = all(set(self.KEYS) <= set(have) for have in venv.get_attr("info_keys"))
        except AttributeError:
            kept = False
        if not kept:
            raise ValueError(
                "VecPrivilegedCritic needs an env whose infos can carry "
                f"{', '.join(self.KEYS)} (follow_env's SB3 adapter: include_info)"
            )
        box = venv.observation_space
        if not isinstance(box, spaces.Box) or len(box.shape) != 1:
            raise ValueError(f"VecPrivilegedCritic needs a flat Box observation, got {box}")
        self.clip_m = float(clip_m)
        self.half_width_px = float(half_width_px)
        n = len(PRIVILEGED)
        low = np.concatenate([box.low, np.array([0.0, -2.0, 0.0, 0.0, 0.0, -1.0, -1.0])])
        high = np.concatenate([box.high, np.array([np.inf, 2.0, 1.0, 1.0, 1.0, clip_m, clip_m])])
        assert low.size == box.shape[0] + n
        space = spaces.Box(low.astype(np.float32), high.astype(np.float32), dtype=np.float32)
        super().__init__(venv, observation_space=space)
        self._start = np.array([1.0, 0.0, 1.0, 0.0, 0.0, clip_m, clip_m], dtype=np.float32)

    def truth(self, infos: list[dict[str, Any]]) -> np.ndarray:
        """Each lane's :data:`PRIVILEGED` entries ``(n, 7)`` float32 from its info."""
        rows = np.empty((len(infos), len(PRIVILEGED)), dtype=np.float64)
        for i, info in enumerate(infos):
            who = float(info["detected_person"])
            rows[i] = (
                info["true_distance_m"],
                np.clip(info["true_offset_px"] / self.half_width_px, -2.0, 2.0),
                float(info["in_frame"]),
                float(who > 0),
                float(who < 0),
                info["wall_clearance_m"],
                info["bystander_clearance_m"],
            )
        rows[:, 5:] = np.clip(rows[:, 5:], -1.0, self.clip_m)
        return rows.astype(np.float32)

    def reset(self) -> VecEnvObs:
        obs = np.asarray(self.venv.reset(), dtype=np.float32)
        return np.concatenate([obs, np.tile(self._start, (len(obs), 1))], axis=1)

    def step_wait(self) -> VecEnvStepReturn:
        obs, rewards, dones, infos = self.venv.step_wait()
        truth = self.truth(infos)
        for i in np.flatnonzero(dones):
            final = infos[i].get("terminal_observation")
            if final is not None:
                infos[i]["terminal_observation"] = np.concatenate(
                    [np.asarray(final, dtype=np.float32), truth[i]]
                )
            truth[i] = self._start
        obs = np.concatenate([np.asarray(obs, dtype=np.float32), truth], axis=1)
        return obs, rewards, dones, infos
