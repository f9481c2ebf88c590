"""Golden rollouts: hashes of full episodes, recorded before a refactor and checked after it.

Every scenario x 3 seeds x {pn, gsmpn, ppo} runs to its end on the single env and on the
vector env (one lane per seed); each episode is hashed over every observation, reward, flag and
``info`` value, bit for bit. So do a few scenarios under other configurations
(:data:`EXTRA_CONFIGS`) and the :data:`GROUPS`, one for every other pair of env and platform:
the line tracer on its mecanum base (every track, both laws), on the differential drive and on
the unicycle, and the person follower on the mecanum base and on the unicycle. Each law is fitted
to the platform's action and the env's control period as evaluation fits it
(:func:`policies.for_platform`, :func:`policies.at_period`). ``tests/golden/rollouts.json``
holds the hashes the tree produced when they were recorded; ``tests/test_golden_rollouts.py``
checks the tree still produces them.

Record anew (only when behaviour changes on purpose, and say why in the commit)::

    .venv/bin/python tests/golden/rollouts.py

Another CPU may compute the same episodes apart in the last bits (seen: every ``occlusion``
episode on an AMD EPYC with AVX-512, first seen 2026-12-02, the same steps, while every other
scenario matched bit for bit). So each episode also keeps a fingerprint that such bits do not
move: a hash of its events (every flag, count and name at every step, as the bit-for-bit hash
takes them) and, per real-valued channel (each observation entry, the reward, each float
``info`` value), a weighted sum over the steps with the sum of magnitudes as its scale (a
value that is not finite, such as the clearance to bystanders where there are none, counts as
an event instead: inf less inf is nan). An
episode passes when it hashes to the recorded one bit for bit, or has the same steps and events
and every channel's sum within :data:`RTOL` of its scale (sums kept to 12 digits): last bits
move a sum by far less (moving every person's waypoints by one unit in the last place moved none
by more than 2e-14 of its scale in any of the 123 person-following episodes on the differential
drive; moving the line tracer's start pose, or the person's waypoints on the other platforms,
the same way moved none of the 102 episodes of :data:`GROUPS` by more than 8e-13), a change of
behaviour by far more
(moving them by a micrometre fails, tested). Learned agents act in float64 and round to float32
(:mod:`policies.learned.networks`), so their episodes are the same on every CPU too, but for a
chance of about one in ten thousand an episode; in float32 they were not (torch's matrix kernels
differ by CPU and 30 s of closed loop made another episode of a last bit, ``crowd/ppo/0`` ending
at step 116 instead of 96 on an Intel Xeon with AVX-512).

A CPU whose episodes still differ beyond that can add its hashes as alternates, with the CPU's
name, beside the recorded ones; the test accepts either. A law's episode must keep the recorded
step count (a different episode is a change of behaviour, not of the CPU); a learned agent's
alternate records its own (:data:`LEARNED`)::

    .venv/bin/python tests/golden/rollouts.py --alternates

Every shipped agent is also pinned open loop, on any CPU, by ``actions.py`` beside this file.
"""

from __future__ import annotations

import hashlib
import json
import math
import platform
import re
import struct
import sys
from pathlib import Path
from typing import Any, NamedTuple

import gymnasium as gym
import numpy as np

import follow_env  # noqa: F401  (registers PersonFollow-v0)
from follow_env.sim.atomic import atomic_write_text
from follow_env.tasks import task_for_env
from policies import Policy, at_period, for_platform, make_policy

GOLDEN = Path(__file__).with_name("rollouts.json")
SCENARIOS = (
    "straight",
    "curve",
    "random",
    "corridor_turn",
    "doorway",
    "occlusion",
    "crossing",
    "crowd",
    "stop_and_go",
    "zigzag",
    "random_world",
)
SEEDS = (0, 1, 2)
POLICIES = ("pn", "gsmpn", "ppo")
#: The learned agents among them: an alternate of theirs may end elsewhere (module docstring).
LEARNED = ("ppo",)
#: How far a channel's weighted sum may be from the recorded one, as a share of its scale (the
#: sum of the channel's magnitudes): far above a CPU's last bits, far below a change.
RTOL = 1e-9
#: And beside it, in the channel's unit summed over the steps: a channel that is zero
#: throughout (the person's y on a straight walk) may gain a CPU's last bits somewhere too.
ATOL = 1e-9
# Beyond the default preset: every randomisation and push, and the tracker association, so the
# streams and branches the thesis preset leaves off are covered too.
EXTRA_CONFIGS: dict[str, Any] = {
    "randomized": "randomized",
    "tracker": {"perception": {"association": "tracker"}},
}
EXTRA_SCENARIOS = ("straight", "random", "crossing", "crowd")
# The info keys that existed when the hashes were recorded (new keys may be added later).
INFO_KEYS = (
    "time_s",
    "robot_x_m",
    "robot_y_m",
    "robot_theta_rad",
    "robot_v_mps",
    "robot_w_radps",
    "true_distance_m",
    "true_offset_px",
    "raw_depth_m",
    "wheel_target_r_mps",
    "wheel_target_l_mps",
    "wheel_measured_r_mps",
    "wheel_measured_l_mps",
    "wheel_true_r_radps",
    "wheel_true_l_radps",
    "duty_r_pct",
    "duty_l_pct",
    "encoder_speed_mps",
    "accel_mps2",
    "wall_clearance_m",
    "person_clearance_m",
    "person_x_m",
    "person_y_m",
    "person_theta_rad",
    "person_v_mps",
    "in_frame",
    "detected",
    "detected_person",
    "step",
    "termination",
)

#: Each platform's wheel info keys when its episodes were recorded (the unicycle has no wheels).
WHEEL_KEYS = {
    "diff_drive": tuple(
        f"{what}_{side}{unit}"
        for what, unit in (("duty", "_pct"), ("wheel_target", "_mps"), ("wheel_measured", "_mps"),
                           ("wheel_true", "_radps"))
        for side in ("l", "r")
    ),
    "mecanum": tuple(
        f"{what}_{wheel}{unit}"
        for what, unit in (("duty", ""), ("wheel_target", "_mps"), ("wheel_measured", "_mps"),
                           ("wheel_true", "_radps"))
        for wheel in ("fl", "fr", "rl", "rr")
    ),
    "unicycle": (),
}  # fmt: skip
#: The person follower's info keys on a platform other than the differential drive (whose
#: episodes keep :data:`INFO_KEYS`, recorded before these keys were added), less the wheels'.
PERSON_KEYS = (
    *(k for k in INFO_KEYS if not k.startswith(("wheel_", "duty_"))),
    "robot_vy_mps",
    "bystander_clearance_m",
)
#: LineTrace-v0's info keys when its episodes were recorded, less the wheels'.
LINE_KEYS = (
    "time_s",
    "step",
    "termination",
    "robot_x_m",
    "robot_y_m",
    "robot_theta_rad",
    "robot_v_mps",
    "robot_vy_mps",
    "robot_w_radps",
    "progress_m",
    "track_length_m",
    "cross_track_m",
    "heading_error_rad",
    "line_seen",
    "in_gap",
    "active_cells",
    "lost_s",
    "accel_mps2",
    "encoder_speed_mps",
)
#: The line tracer's built-in tracks (``follow_env.tasks.line_trace.tracks.builtin``), named
#: here: tests register tracks of their own in the same registry.
LINE_TRACKS = ("straight", "corners", "curves", "zigzag", "gaps", "course", "random")


class Group(NamedTuple):
    """Golden episodes of another env or platform: ``label:<variant>/<policy>/<seed>``.

    :param label: the episodes' name prefix.
    :param env_id: the Gymnasium id.
    :param platform: the platform (``gym.make``'s ``platform=``).
    :param variants: its scenarios or tracks (the task's ``variant_key``).
    :param policies: the laws run (by name, for the env's task).
    :param info_keys: the ``info`` values hashed.
    """

    label: str
    env_id: str
    platform: str
    variants: tuple[str, ...]
    policies: tuple[str, ...]
    info_keys: tuple[str, ...]


#: Every other (env, platform) pair: the line tracer on its mecanum base (every track, both
#: laws) and, with the PID law (coordinate control strafes), on the two platforms that cannot;
#: the person follower on the mecanum base and the unicycle.
GROUPS = (
    Group("line", "LineTrace-v0", "mecanum", LINE_TRACKS, ("pid", "coordinate"),
          (*LINE_KEYS, *WHEEL_KEYS["mecanum"])),
    Group("line_diff_drive", "LineTrace-v0", "diff_drive", ("corners", "gaps"), ("pid",),
          (*LINE_KEYS, *WHEEL_KEYS["diff_drive"])),
    Group("line_unicycle", "LineTrace-v0", "unicycle", ("corners", "gaps"), ("pid",), LINE_KEYS),
    Group("mecanum", "PersonFollow-v0", "mecanum", EXTRA_SCENARIOS, ("pn", "gsmpn"),
          (*PERSON_KEYS, *WHEEL_KEYS["mecanum"])),
    Group("unicycle", "PersonFollow-v0", "unicycle", EXTRA_SCENARIOS, ("pn", "gsmpn"),
          PERSON_KEYS),
)  # fmt: skip


class EpisodeHash:
    """Accumulates one episode: every value in a fixed order, floats as IEEE-754 doubles, and
    its fingerprint (module docstring): the events hashed, each real channel's weighted sum."""

    def __init__(self, info_keys: tuple[str, ...] = INFO_KEYS) -> None:
        self._info_keys = info_keys
        self._h = hashlib.sha256()
        self._events = hashlib.sha256()
        # channel -> [sum of w_t x_t, sum of |x_t|] over the steps t
        self._sums: dict[str, list[float]] = {}
        self.steps = 0

    def _value(self, key: str, value: Any) -> None:
        if isinstance(value, bool | np.bool_):
            flag = b"T" if value else b"F"
            self._h.update(flag)
            self._events.update(flag)
        elif isinstance(value, int | np.integer):
            packed = struct.pack("<q", int(value))
            self._h.update(packed)
            self._events.update(packed)
        elif isinstance(value, float | np.floating):
            self._h.update(struct.pack("<d", float(value)))
            self._real(key, float(value))
        elif isinstance(value, str):
            self._h.update(value.encode() + b"\0")
            self._events.update(value.encode() + b"\0")
        else:
            raise TypeError(f"cannot hash {value!r}")

    def _real(self, key: str, value: float) -> None:
        if not math.isfinite(value):
            # An event, not a sum: inf - inf is nan, so a channel that is inf (no bystander's
            # clearance) would fail the fingerprint on any CPU whose last bits differ.
            # nan by name: its bits (sign, payload) may differ by CPU
            mark = b"nan" if math.isnan(value) else struct.pack("<d", value)
            self._events.update(key.encode() + b"\0" + mark)
            return
        # The weight varies with the step, so values moved between steps move the sum too.
        weight = 1.0 + 0.5 * math.sin(0.7 * self.steps)
        sums = self._sums.setdefault(key, [0.0, 0.0])
        sums[0] += weight * value
        sums[1] += abs(value)

    def add(
        self, obs: np.ndarray, reward: float, terminated: bool, truncated: bool, info: dict
    ) -> None:
        row = np.ascontiguousarray(obs, dtype=np.float32)
        self._h.update(row.tobytes())
        for i, entry in enumerate(row.ravel()):
            self._real(f"obs[{i}]", float(entry))
        for key, value in (
            ("reward", float(reward)),
            ("terminated", bool(terminated)),
            ("truncated", bool(truncated)),
        ):
            self._value(key, value)
        for key in self._info_keys:
            self._value(key, info[key])
        self.steps += 1

    def hexdigest(self) -> str:
        return self._h.hexdigest()

    def record(self) -> dict[str, Any]:
        """The episode as ``rollouts.json`` keeps it: its hash, steps and fingerprint."""
        return {
            "sha256": self.hexdigest(),
            "steps": self.steps,
            "events": self._events.hexdigest(),
            # 12 significant digits: within 1e-12 of the sum, far inside RTOL
            "sums": {
                key: [float(f"{v:.12g}") for v in sums] for key, sums in sorted(self._sums.items())
            },
        }


def same_within_rtol(got: dict[str, Any], want: dict[str, Any]) -> str | None:
    """None if episode record ``got`` has ``want``'s steps and events and every channel's sum
    within :data:`RTOL` of its scale and :data:`ATOL` (module docstring); else what differs."""
    if "events" not in want:
        return "no fingerprint was recorded"
    if (got["steps"], got["events"]) != (want["steps"], want["events"]):
        return f"other events: {got['steps']} steps, recorded {want['steps']}"
    if set(got["sums"]) != set(want["sums"]):
        return "other channels"
    for key, (total, scale) in want["sums"].items():
        off = abs(got["sums"][key][0] - total)
        if not off <= RTOL * scale + ATOL:
            return f"{key}: weighted sum {got['sums'][key][0]!r}, recorded {total!r}"
    return None


class Case(NamedTuple):
    """One golden (env, platform, variant, policy, configuration), run on :data:`SEEDS`.

    :param prefix: the episodes' name before ``/<seed>``.
    :param env_id: the Gymnasium id.
    :param variant: the scenario or track.
    :param policy: the policy's name, for the env's task.
    :param config: the ``config`` keyword (None: the env's default).
    :param platform: the ``platform`` keyword (None: the env's own).
    :param info_keys: the ``info`` values hashed.
    """

    prefix: str
    env_id: str
    variant: str
    policy: str
    config: Any = "thesis"
    platform: str | None = None
    info_keys: tuple[str, ...] = INFO_KEYS

    def env_kwargs(self) -> dict[str, Any]:
        """``gym.make``'s keywords after the id."""
        kwargs: dict[str, Any] = {task_for_env(self.env_id).variant_key: self.variant}
        if self.config is not None:
            kwargs["config"] = self.config
        if self.platform is not None:
            kwargs["platform"] = self.platform
        return kwargs

    def law(self, env: gym.Env | gym.vector.VectorEnv) -> Policy:
        """The policy fitted to ``env``'s action and control period, as evaluation fits it."""
        base = env.unwrapped
        built = make_policy(self.policy, task_for_env(self.env_id).name)
        names = tuple(a.name for a in base.sim.platform.actions)
        return for_platform(at_period(built, base.config.episode.control_dt_s), names)


def person_follow(scenario: str, policy: str, config: Any = "thesis", label: str = "") -> Case:
    """A :class:`Case` of PersonFollow-v0 on the differential drive."""
    prefix = f"{label}:{scenario}/{policy}" if label else f"{scenario}/{policy}"
    return Case(prefix, "PersonFollow-v0", scenario, policy, config)


def episode_hash(case: Case, seed: int) -> dict[str, Any]:
    """The record of one episode of ``case`` on the single env (:meth:`EpisodeHash.record`)."""
    env = gym.make(case.env_id, **case.env_kwargs())
    law = case.law(env)
    obs, info = env.reset(seed=seed)
    law.reset()
    h = EpisodeHash(case.info_keys)
    h.add(obs, 0.0, False, False, info)
    done = False
    while not done:
        obs, reward, terminated, truncated, info = env.step(law.act(obs))
        h.add(obs, reward, terminated, truncated, info)
        done = terminated or truncated
    env.close()
    return h.record()


def lane_hashes(case: Case, seeds: tuple[int, ...]) -> list[str]:
    """The hash of each lane's first episode of ``case`` on the vector env (lane i seeded
    seeds[0] + i)."""
    n = len(seeds)
    envs = gym.make_vec(
        case.env_id, num_envs=n, vectorization_mode="vector_entry_point", **case.env_kwargs()
    )
    laws = [case.law(envs) for _ in range(n)]
    obs, info = envs.reset(seed=seeds[0])
    hashes = [EpisodeHash(case.info_keys) for _ in range(n)]
    done = np.zeros(n, dtype=bool)

    def lane_info(i: int) -> dict[str, Any]:
        return {k: info[k][i] for k in case.info_keys}

    for i, law in enumerate(laws):
        law.reset()
        hashes[i].add(obs[i], 0.0, False, False, lane_info(i))
    rest = np.zeros(envs.single_action_space.shape, np.float32)  # a finished lane's: ignored
    while not done.all():
        actions = np.stack([rest if done[i] else law.act(obs[i]) for i, law in enumerate(laws)])
        obs, reward, terminated, truncated, info = envs.step(actions)
        for i in np.flatnonzero(~done):
            hashes[i].add(obs[i], reward[i], terminated[i], truncated[i], lane_info(i))
        done |= terminated | truncated
    envs.close()
    return [h.hexdigest() for h in hashes]


def cases() -> list[Case]:
    """Every golden case: PersonFollow's scenarios and laws, its extra configurations, and the
    other tasks and platforms (:data:`GROUPS`)."""
    out = [person_follow(s, p) for s in SCENARIOS for p in POLICIES]
    for label, config in EXTRA_CONFIGS.items():
        out += [person_follow(s, "pn", config, label) for s in EXTRA_SCENARIOS]
    for g in GROUPS:
        out += [
            Case(f"{g.label}:{v}/{p}", g.env_id, v, p, None, g.platform, g.info_keys)
            for v in g.variants
            for p in g.policies
        ]
    return out


def record() -> dict[str, Any]:
    """Run every golden episode; returns the JSON document."""
    episodes: dict[str, dict[str, Any]] = {}
    for case in cases():
        lanes = lane_hashes(case, SEEDS)
        for seed, lane_hash in zip(SEEDS, lanes, strict=True):
            episode = episode_hash(case, seed)
            if episode["sha256"] != lane_hash:
                raise AssertionError(f"{case.prefix}/{seed}: vector lane != single env")
            episodes[f"{case.prefix}/{seed}"] = episode
    return {
        "recorded_on": {
            "machine": platform.machine(),
            "python": platform.python_version(),
            "numpy": np.__version__,
            "cpu": cpu_name(),
        },
        "info_keys": list(INFO_KEYS),  # the person follower's on the differential drive
        "group_info_keys": {g.label: list(g.info_keys) for g in GROUPS},
        "episodes": episodes,
    }


def policy_of(name: str) -> str:
    """The policy of an episode's name (``[<config>:]<scenario>/<policy>/<seed>``)."""
    return name.split("/")[-2]


def accepted(name: str, doc: dict[str, Any]) -> set[tuple[str, int]]:
    """The ``(sha256, steps)`` pairs episode ``name`` may hash to: the recorded one and its
    alternates (each with the recorded steps unless it carries its own, :func:`add_alternates`)."""
    want = doc["episodes"][name]
    alternates = doc.get("alternates", {}).get(name, [])
    return {(want["sha256"], want["steps"])} | {
        (a["sha256"], a.get("steps", want["steps"])) for a in alternates
    }


def verdict(name: str, got: dict[str, Any], doc: dict[str, Any]) -> str | None:
    """None if episode ``name``'s record ``got`` passes (module docstring): it hashes to an
    accepted pair (:func:`accepted`), or its fingerprint is the recorded one's within
    :data:`RTOL`; else what differs."""
    if (got["sha256"], got["steps"]) in accepted(name, doc):
        return None
    return same_within_rtol(got, doc["episodes"][name])


def cpu_name() -> str:
    """The CPU's model name (Linux's ``/proc/cpuinfo``), else the machine type."""
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.exists():
        for line in cpuinfo.read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    return platform.machine()


def add_alternates(doc: dict[str, Any]) -> int:
    """Add this machine's hash of each episode that fails ``doc``'s (:func:`verdict`) as an
    alternate (a law's with the same steps: a different episode is a change of behaviour, not of the
    CPU; a learned agent's with its own, module docstring)."""
    fresh = record()["episodes"]
    alternates = doc.setdefault("alternates", {})
    added = 0
    for name, want in doc["episodes"].items():
        got = fresh[name]
        if verdict(name, got, doc) is None:
            continue
        entry = {"sha256": got["sha256"], "cpu": cpu_name(), "numpy": np.__version__}
        if got["steps"] != want["steps"]:
            if policy_of(name) not in LEARNED:
                raise AssertionError(f"{name}: {got['steps']} steps, recorded {want['steps']}")
            entry["steps"] = got["steps"]
        known = alternates.setdefault(name, [])
        if all(a["sha256"] != got["sha256"] for a in known):
            known.append(entry)
            added += 1
    return added


def write(doc: dict[str, Any]) -> None:
    """Write ``doc`` to :data:`GOLDEN` atomically, each channel's pair of sums on one line."""
    text = json.dumps(doc, indent=1, sort_keys=True) + "\n"
    atomic_write_text(GOLDEN, re.sub(r"\[\n\s*(\S+),\n\s*(\S+)\n\s*\]", r"[\1, \2]", text))


if __name__ == "__main__":
    if "--alternates" in sys.argv[1:]:
        doc = json.loads(GOLDEN.read_text())
        n = add_alternates(doc)
        what = f"added {n} alternate hashes"
    else:
        doc = record()
        what = f"wrote {len(doc['episodes'])} episode hashes"
    write(doc)
    print(f"{what} to {GOLDEN}", file=sys.stderr)
