"""``follow-robot monitor --sim``: the simulator driven live, so any policy can be watched
without hardware.

One ``PersonFollow-v0`` env steps in real time (one control step per ``control_dt_s``) on its
own thread; the monitor's mode picks what acts (a guidance law, the PPO agent, the browser's
manual command, or stop), and every step is published to the hub. When an episode ends, the
next one starts after a second's pause, with the next seed.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from bridge.monitor.hub import MonitorHub
from bridge.world import scene_walls
from follow_env.tasks.person_follow.env import PersonFollowEnv
from follow_env.tasks.person_follow.spec import ahead_settings
from policies.adapt import for_platform

__all__ = ["SimDriver"]


class SimDriver:
    """Step an env in real time under the hub's mode.

    :param hub: where to publish and read the mode.
    :param policy_factory: builds the policy of a mode name (``"gsmpn"`` -> a law).
    :param scenario: the scenario to run.
    :param seed: the first episode's seed (the next episodes count up).
    :param config: the env's configuration (preset name, object or overrides).
    :param speed: simulated seconds per wall-clock second (1 = real time).
    """

    def __init__(
        self,
        hub: MonitorHub,
        policy_factory: Callable[[str], Any],
        scenario: str = "straight",
        seed: int = 0,
        config: Any = None,
        speed: float = 1.0,
    ) -> None:
        if not 0.1 <= speed <= 100.0:
            raise ValueError(f"speed={speed} is out of range: must be in [0.1, 100]")
        self.hub = hub
        self.policy_factory = policy_factory
        self.env = PersonFollowEnv(config=config, scenario=scenario)
        self.seed = seed
        self.speed = speed
        self.dt = self.env.config.episode.control_dt_s
        self._actions = tuple(a.name for a in self.env.sim.platform.actions)
        self._v, self._w = self._actions.index("v_mps"), self._actions.index("w_radps")
        self._policies: dict[str, Any] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="sim-driver", daemon=True)
        self.episodes = 0

    def start(self) -> SimDriver:
        """Start stepping in the background."""
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop stepping (idempotent)."""
        self._stop.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)

    def _policy(self, mode: str) -> Any:
        if mode not in self._policies:
            self._policies[mode] = self.runnable(self.policy_factory(mode))
            self._policies[mode].reset()
        return self._policies[mode]

    def runnable(self, policy: Any) -> Any:
        """``policy`` acting in this env's platform action (:func:`~policies.adapt.for_platform`:
        a law's ``[v, w]`` on the mecanum base has ``vy = 0``; an agent runs only on the
        platform it was trained on), if what it reads ahead is what the env publishes;
        ``ValueError`` naming the difference if not."""
        name = getattr(policy, "name", "the policy")
        adapted = for_platform(policy, self._actions)
        wanted = getattr(policy, "reads_ahead", None)
        given = ahead_settings(self.env.config.perception)
        if wanted and wanted != given:
            raise ValueError(
                f"{name} reads the reading ahead with {wanted}, but the simulation publishes "
                + ("none" if given is None else f"it with {given}")
            )
        return adapted

    def check(self, mode: str) -> None:
        """Build the policy of ``mode`` now (a bad name or a policy this env cannot feed fails
        here, as a ``ValueError``, not in the driver's thread)."""
        if mode not in ("stop", "manual"):
            self._policy(mode)

    def _switch(self, mode: str, new: str) -> str:
        """The mode that acts after the browser chose ``new``: ``new``, or ``mode`` if the env
        cannot feed it (the hub is told why)."""
        if new in ("stop", "manual"):
            return new
        try:
            policy = self._policy(new)
        except ValueError as exc:
            self.hub.refuse(new, mode, str(exc))
            return mode
        policy.reset()
        return new

    def _act(self, mode: str, obs: np.ndarray) -> np.ndarray:
        action = np.zeros(len(self._actions))
        if mode == "manual":  # the browser's [v, w] (a mecanum base: vy = 0)
            action[[self._v, self._w]] = self.hub.manual_command()
        elif mode != "stop":
            action[:] = self._policy(mode).act(obs)
        return action

    def _run(self) -> None:
        mode = "stop"
        while not self._stop.is_set():
            obs, info = self.env.reset(seed=self.seed + self.episodes)
            self.episodes += 1
            self.hub.scene = {"walls": scene_walls(self.env)}
            for policy in self._policies.values():
                policy.reset()
            if self.hub.mode != mode:
                mode = self._switch(mode, self.hub.mode)
            action = np.zeros(len(self._actions))
            self._publish(info, obs, action, mode)
            start = time.monotonic()
            step = 0
            done = False
            while not done and not self._stop.is_set():
                step += 1
                delay = start + step * self.dt / self.speed - time.monotonic()
                if delay > 0 and self._stop.wait(delay):
                    return
                if self.hub.mode != mode:  # a new mode starts from a fresh memory
                    mode = self._switch(mode, self.hub.mode)
                action = self._act(mode, obs)
                obs, _, terminated, truncated, info = self.env.step(action)
                done = terminated or truncated
                self._publish(info, obs, action, mode)
            self._stop.wait(1.0)

    def _publish(
        self, info: dict[str, Any], obs: np.ndarray, action: np.ndarray, mode: str
    ) -> None:
        self.hub.publish(
            {
                "time_s": float(info["time_s"]),
                "mode": mode,
                "obs": [float(x) for x in obs],  # with ahead_m when the config publishes it
                "detected": bool(info["detected"]),
                "command": [float(action[self._v]), float(action[self._w])],
                # every wheel of the platform, in the env's order (right, left; or four)
                "wheel_target_mps": [v for k, v in info.items() if k.startswith("wheel_target_")],
                "wheel_measured_mps": [
                    v for k, v in info.items() if k.startswith("wheel_measured_")
                ],
                "robot": [info["robot_x_m"], info["robot_y_m"], info["robot_theta_rad"]],
                "person": [info["person_x_m"], info["person_y_m"], info["person_theta_rad"]],
                "link": None,
                "termination": info["termination"],
                "episode": self.episodes,
            }
        )
