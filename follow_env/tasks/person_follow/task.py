"""PersonFollow as the runner sees it: its blocks, world arrays, resets, observations and info.

The compiled part is in :mod:`.kernel` (with :mod:`.perception` and :mod:`.reward`); this module
is the numpy side: the task's parameter and state blocks (the camera's, the detector's and the
depth stream's nested inside), the per-lane world (people, their paths, walls), what a reset
does before the kernel runs (the scenario, the sensors' randomisation), and how observations and
the ``info`` dict are read from the state.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, NamedTuple

import numpy as np
from gymnasium import spaces

from follow_env.platforms.base import Platform, PlatformConfig
from follow_env.sensors import camera, depth, detector
from follow_env.sensors.detector import PEOPLE_MAX
from follow_env.sim.runner import BatchedSim
from follow_env.sim.schema import Block, f8, float_column, i8, nested
from follow_env.tasks.config import TaskPlatforms, resolve_config, section_or_name
from follow_env.tasks.person_follow import reward
from follow_env.tasks.person_follow.config import PRESETS, THESIS, EnvConfig, ScenarioConfig
from follow_env.tasks.person_follow.people import PERSON, WAYPOINT
from follow_env.tasks.person_follow.scenarios import ScenarioSpec, get_scenario
from follow_env.tasks.person_follow.spec import SPEC, observation_bounds, observation_size
from follow_env.world.geometry import WALL, WALL_RADIUS_M

__all__ = ["PARAMS", "STATE", "TASK", "PersonFollowTask", "batched_sim"]

N_OCCLUDERS = 64
"""Most occluders listed for one sight line."""

PARAMS = Block(
    "person_follow_params",
    "the camera, the detector, depth, the people, the reward and the episode",
    [
        nested("camera", camera.PARAMS),
        nested("detector", detector.PARAMS),
        nested("depth", depth.PARAMS),
        nested("reward", reward.PARAMS),
        f8("person_h", "m", "body height", source="person.height_m"),
        f8("person_w", "m", "body width", source="person.width_m"),
        f8("person_d", "m", "body depth", source="person.depth_m"),
        f8("person_accel", "m/s^2", "walking acceleration", source="person.accel_mps2"),
        f8("person_decel", "m/s^2", "walking deceleration", source="person.decel_mps2"),
        f8("social_radius", "m", "people step aside within this", source="person.social_radius_m"),
        f8(
            "social_strength",
            "m/s^2",
            "social force strength",
            source="person.social_strength_mps2",
        ),
        f8("dt", "s", "control period", source="episode.control_dt_s"),
        f8("max_steps", "steps", "episode step cap", source="episode.max_steps"),
        f8("lost_timeout", "s", "lost after this long undetected", source="episode.lost_timeout_s"),
        f8(
            "clearance",
            "m",
            "closer to the target is a collision",
            source="episode.person_clearance_m",
        ),
        f8(
            "settle",
            "s",
            "the episode runs on this long after the walk",
            source="scenario.settle_s",
        ),
        f8("wall_radius", "m", "half a wall's thickness", source=lambda c: WALL_RADIUS_M),
    ],
)

STATE = Block(
    "person_follow_state",
    "what the perception publishes, the ground truth, and the people and walls in use",
    [
        nested("detector", detector.STATE),
        nested("filter", depth.STATE),
        f8("obs_d", "m", "published distance (observation 0)"),
        f8("obs_o", "px", "published offset (observation 1)"),
        f8("obs_ahead", "m", "the reading ahead (observation 2, when configured)"),
        f8("detected", "", "1: this step's observation is a fresh detection"),
        i8("detected_id", "", "whose detection is published (-1: none)"),
        f8("raw_depth", "m", "unfiltered depth of the published detection"),
        f8("box", "px", "published box u1, v1, u2, v2", shape=(4,)),
        f8("lost_t", "s", "time since the last published detection"),
        f8("true_d", "m", "camera to the front of the target's body"),
        f8("true_o", "px", "image column of the target's axis - width // 2"),
        f8("in_frame", "", "1: enough of the target in the image and in sight"),
        f8("vis_frac", "", "the target's visible share"),
        f8("walk_end_t", "s", "when the target's walk ended (-1: not yet)"),
        f8("clear_wall", "m", "footprint to the nearest wall"),
        f8("clear_person", "m", "footprint to the target"),
        f8("clear_other", "m", "footprint to the nearest bystander (inf: none)"),
        f8(
            "reward_terms",
            "",
            "this step's reward terms (reward.TERMS)",
            shape=(len(reward.TERMS),),
        ),
        i8("n_people", "", "people in the lane (the target first)"),
        i8("n_walls", "", "wall segments in the lane"),
        i8("n_points", "", "waypoints of each person's path", shape=(PEOPLE_MAX,)),
        f8("corners", "", "scratch: a body's 8 corners in the camera frame", shape=(24,)),
        i8("occluders", "", "scratch: occluders listed for a sight line", shape=(N_OCCLUDERS,)),
    ],
)

# info keys read straight from a state field: (key, path into the lane's state record).
_STATE_INFO: dict[str, tuple[str, ...]] = {
    "time_s": ("episode", "t"),
    "robot_x_m": ("body", "x"),
    "robot_y_m": ("body", "y"),
    "robot_theta_rad": ("body", "th"),
    "robot_v_mps": ("body", "v"),
    "robot_w_radps": ("body", "w"),
    "robot_vy_mps": ("body", "vy"),
    "true_distance_m": ("task", "true_d"),
    "true_offset_px": ("task", "true_o"),
    "raw_depth_m": ("task", "raw_depth"),
    "encoder_speed_mps": ("body", "v_meas"),
    "accel_mps2": ("body", "accel"),
    "wall_clearance_m": ("task", "clear_wall"),
    "person_clearance_m": ("task", "clear_person"),
    "bystander_clearance_m": ("task", "clear_other"),
}
# ... from the target person's record.
_PERSON_INFO = {"person_x_m": "x", "person_y_m": "y", "person_theta_rad": "th", "person_v_mps": "v"}
_REASONS = np.array(SPEC.terminations, dtype=object)


class _InfoColumns(NamedTuple):
    names: tuple[str, ...]  # the float keys (body, task, platform), in the info dict's order
    cols: np.ndarray  # their words, then the in_frame and detected flags'
    n_float: int
    int_cols: np.ndarray  # detected_id, step, reason
    person_names: tuple[str, ...]
    person_cols: np.ndarray
    obs: int  # the first observation word
    names_and_person: tuple[str, ...]


def _int_column(dtype: np.dtype, path: tuple[str, ...]) -> int:
    """Like :func:`float_column`, for an int64 field."""
    offset, current = 0, dtype
    for name in path:
        current, off = current.fields[name][:2]
        offset += off
    if current != np.dtype(np.int64) or offset % 8:
        raise ValueError(f"{'.'.join(path)} is not an int64 field on an 8-byte boundary")
    return offset // 8


class PersonFollowTask(TaskPlatforms):
    """The person-following task (reference §1) for the runner and the env faces."""

    def __init__(self) -> None:
        self._column_cache: dict[tuple[Any, ...], _InfoColumns] = {}

    name = SPEC.name
    spec = SPEC
    kernel_module = "follow_env.tasks.person_follow.kernel"
    params = PARAMS
    state = STATE
    config_class = EnvConfig
    presets = PRESETS
    default_config = THESIS

    # -- configuration -------------------------------------------------------------------------

    def resolve_config(
        self,
        config: EnvConfig | str | dict[str, Any] | None = None,
        scenario: str | ScenarioConfig | Mapping[str, Any] | None = None,
        platform: str | PlatformConfig | Mapping[str, Any] | None = None,
        **overrides: Any,
    ) -> EnvConfig:
        """Build an :class:`EnvConfig` from ``gym.make`` keyword arguments.

        :param config: a preset name (``"thesis"``, ``"ideal"``, ``"noisy"``, ``"randomized"``),
            an ``EnvConfig``, or a mapping of section overrides applied to the ``thesis`` preset.
        :param scenario: a scenario name (shorthand for ``scenario={"name": ...}``), or the
            ``scenario`` section itself (a ``ScenarioConfig`` or a mapping of its fields).
        :param platform: a platform name (its default configuration), a platform config
            object, or a mapping ``{"name": ..., <section>: {...}}``; sections of the platform
            may still be overridden (``robot={...}``), in ``config`` too.
        :param overrides: sections (``perception={...}``) or ``section__field=value`` pairs.
        """
        return resolve_config(
            EnvConfig,
            PRESETS,
            THESIS,
            config,
            platform,
            shorthands=section_or_name("scenario", scenario),
            overrides=overrides,
        )

    def spaces(self, cfg: EnvConfig, platform: Platform) -> tuple[spaces.Box, spaces.Box]:
        """``(observation_space, action_space)`` of one robot, float32: ``[distance_m,
        offset_px]`` (and ``ahead_m`` when configured) and the platform's action, bounded by
        what it can do."""
        low, high = observation_bounds(
            cfg.camera.width_px, cfg.camera.depth_max_m, ahead=cfg.perception.ahead_rays > 0
        )
        observation = spaces.Box(
            np.array(low, np.float32), np.array(high, np.float32), dtype=np.float32
        )
        return observation, self.action_space(cfg, platform)

    def variants(self) -> list[str]:
        """The task's registered variants (here: scenarios), which training spreads lanes over
        and evaluation tabulates (``variant_key`` is their ``gym.make`` keyword)."""
        from follow_env.tasks.person_follow.scenarios import SCENARIOS

        return sorted(SCENARIOS)

    variant_key = "scenario"

    def renderer(self, cfg: EnvConfig) -> Any:
        """A renderer of this task's frames (OpenCV, headless)."""
        from follow_env.tasks.person_follow.render import Renderer

        return Renderer(cfg)

    def scenario(self, cfg: EnvConfig) -> ScenarioSpec:
        """The configured scenario (``ValueError`` naming the field when unknown)."""
        return get_scenario(cfg.scenario.name)

    def check(self, cfg: EnvConfig) -> None:
        """Refuse what the configured scenario cannot use, and too many people."""
        spec = self.scenario(cfg)
        spec.check(cfg)
        if spec.max_people > PEOPLE_MAX:
            raise ValueError(
                f"scenario {spec.name!r} declares {spec.max_people} people; the detector "
                f"tracks at most {PEOPLE_MAX}"
            )

    # -- the runner's side -----------------------------------------------------------------------

    def world(self, cfg: EnvConfig, num_lanes: int) -> tuple[np.ndarray, ...]:
        """``(people, paths, walls)``: records per lane, sized by the scenario."""
        spec = self.scenario(cfg)
        return (
            PERSON.zeros(num_lanes, spec.max_people),
            WAYPOINT.zeros(num_lanes, spec.max_people, spec.points_for(cfg)),
            WALL.zeros(num_lanes, spec.max_walls),
        )

    def prepare_reset(self, sim: BatchedSim, lanes: np.ndarray, keys: np.ndarray) -> np.ndarray:
        """Run the scenario for ``lanes``, write their people's paths and walls, draw the
        sensors' per-episode randomisation; return the robots' start poses."""
        spec = self.scenario(sim.cfg)
        batch = spec.fn(spec.random(keys), sim.cfg)
        _, paths, walls = sim.world
        n_people_max, n_pts, n_w = batch.paths.shape[1], batch.paths.shape[2], batch.walls.shape[1]
        if n_people_max > paths.shape[1] or n_pts > paths.shape[2] or n_w > walls.shape[1]:
            raise ValueError(
                f"scenario {spec.name!r} returned {n_people_max} people x {n_pts} points "
                f"and {n_w} walls, more than it registered"
            )
        # Scenario arrays are plain floats whose columns are the records' fields.
        flat_paths = paths.view(np.float64).reshape(*paths.shape, -1)
        flat_walls = walls.view(np.float64).reshape(*walls.shape, -1)
        flat_paths[lanes] = 0.0
        flat_paths[lanes, :n_people_max, :n_pts] = batch.paths
        flat_walls[lanes] = 0.0
        flat_walls[lanes, :n_w] = batch.walls
        ts = sim.state["task"]
        ts["n_people"][lanes] = batch.n_people
        ts["n_walls"][lanes] = batch.n_walls
        n_points = np.zeros((lanes.size, PEOPLE_MAX), dtype=np.int64)
        n_points[:, : batch.n_points.shape[1]] = batch.n_points
        ts["n_points"][lanes] = n_points
        prm, base = sim.params["task"], sim.base_params["task"]
        camera.randomize(prm["camera"], lanes, sim.cfg, keys)
        detector.randomize(prm["detector"], base["detector"], lanes, sim.cfg, keys)
        depth.randomize(prm["depth"], base["depth"], lanes, sim.cfg, keys)
        # Whose look each person's detections carry: their own, or the scenario's look-alikes.
        look_of = np.tile(np.arange(PEOPLE_MAX, dtype=np.float64), (lanes.size, 1))
        if batch.look_of is not None:
            look_of[:, : batch.look_of.shape[1]] = batch.look_of
        prm["detector"]["look_of"][lanes] = look_of
        return batch.robot_pose

    # -- what the env faces read ---------------------------------------------------------------

    def observations(self, sim: BatchedSim) -> np.ndarray:
        """The published observations of every lane, ``(N, k)`` float32 (k: 2, or 3 with
        the reading ahead)."""
        c = self._columns(sim)
        return sim.state_words[:, c.obs : c.obs + observation_size(sim.cfg)].astype(np.float32)

    def _columns(self, sim: BatchedSim) -> _InfoColumns:
        """Where every info value sits in a lane's records seen as 8-byte words, in the info
        dict's order (generated from the blocks, once per composed layout)."""
        columns = sim.__dict__.get("_info_columns")  # per runner: no hashing of dtypes a step
        if columns is not None:
            return columns
        key = (sim.state_dtype, sim.world[0].dtype, sim.platform.name)
        columns = self._column_cache.get(key)
        if columns is None:
            dtype = sim.state_dtype
            entries = dict(_STATE_INFO)
            names: list[str] = []
            cols: list[int] = []
            for name in self.info_keys(sim.platform):
                if name in entries:
                    names.append(name)
                    cols.append(float_column(dtype, entries[name]))
                platform_entry = next((e for e in sim.platform.info if e[0] == name), None)
                if platform_entry is not None:
                    names.append(name)
                    cols.append(
                        float_column(dtype, ("platform", platform_entry[1]), platform_entry[2] or 0)
                    )
            flags = [float_column(dtype, ("task", f)) for f in ("in_frame", "detected")]
            ints = [
                _int_column(dtype, path)
                for path in (("task", "detected_id"), ("episode", "step"), ("episode", "reason"))
            ]
            person = [float_column(sim.world[0].dtype, (f,)) for f in _PERSON_INFO.values()]
            obs = float_column(dtype, ("task", "obs_d"))
            adjacent = [float_column(dtype, ("task", f)) for f in ("obs_o", "obs_ahead")]
            if adjacent != [obs + 1, obs + 2]:
                raise AssertionError("the observation's fields must be adjacent")
            columns = _InfoColumns(
                tuple(names),
                np.array(cols + flags),
                len(names),
                np.array(ints),
                tuple(_PERSON_INFO),
                np.array(person),
                obs,
                (*names, *_PERSON_INFO),
            )
            self._column_cache[key] = columns
        sim.__dict__["_info_columns"] = columns
        return columns

    def observation(self, sim: BatchedSim, lane: int) -> np.ndarray:
        """The published observation of one lane, ``(k,)`` float32 (as :meth:`observations`)."""
        c = self._columns(sim)
        return sim.state_words[lane, c.obs : c.obs + observation_size(sim.cfg)].astype(np.float32)

    def lane_info(self, sim: BatchedSim, lane: int) -> dict[str, Any]:
        """The ``info`` dict of one lane, as Python scalars."""
        c = self._columns(sim)
        # Row first, then the columns: about twice as fast as one 2-D fancy index.
        values = sim.state_words[lane][c.cols].tolist()
        people = sim.world_words[0][lane][c.person_cols].tolist()
        info = dict(zip(c.names_and_person, values[: c.n_float] + people))  # noqa: B905
        detected_id, step, reason = sim.state_ints[lane][c.int_cols].tolist()
        info["in_frame"] = values[c.n_float] > 0.0
        info["detected"] = values[c.n_float + 1] > 0.0
        info["detected_person"] = detected_id
        info["step"] = step
        info["termination"] = SPEC.terminations[reason]
        return info

    def batch_info(self, sim: BatchedSim, lanes: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """The ``info`` of many lanes as Gymnasium's dict of arrays (all lanes, or those in
        ``lanes``), without the ``_key`` masks."""
        c = self._columns(sim)
        sel = slice(None) if lanes is None else lanes
        # One fresh (keys, lanes) block whose rows are the entries: gathering rows of the
        # transposed view is much faster than transposing a gathered copy at 4096 lanes.
        floats = sim.state_words[sel].T[c.cols]
        info: dict[str, Any] = dict(zip(c.names, floats[: c.n_float], strict=True))
        person = sim.world_words[0][sel].T[c.person_cols]
        info.update(zip(c.person_names, person, strict=True))
        detected_id, step, reason = sim.state_ints[sel].T[c.int_cols]
        info["in_frame"] = floats[c.n_float] > 0.0
        info["detected"] = floats[c.n_float + 1] > 0.0
        info["detected_person"] = detected_id
        info["step"] = step
        info["termination"] = _REASONS[reason]
        return info

    def termination(self, sim: BatchedSim, lane: int) -> str:
        """Why lane ``lane``'s episode ended (``""`` while it runs)."""
        return SPEC.terminations[int(sim.episode["reason"][lane])]


TASK = PersonFollowTask()
"""The task model the env faces use."""


def batched_sim(cfg: EnvConfig, num_lanes: int) -> BatchedSim:
    """A runner of ``num_lanes`` person-following lanes under ``cfg`` (for tools and tests)."""
    return BatchedSim(TASK, cfg, num_lanes)
