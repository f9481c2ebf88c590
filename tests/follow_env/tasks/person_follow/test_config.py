"""Config validation: every field is checked against its declared range."""

from __future__ import annotations

import dataclasses
import math

import pytest

from follow_env.platforms.diff_drive import RobotConfig
from follow_env.platforms.wheels import MotorConfig
from follow_env.sensors.camera import CameraConfig
from follow_env.sensors.detector import PerceptionConfig
from follow_env.sim.config import field_spec
from follow_env.tasks.person_follow.config import IDEAL, PRESETS, THESIS, EnvConfig

_SECTIONS = {name: type(section) for name, section in THESIS.leaf_sections().items()}


def _ranged_fields() -> list[tuple[type, str]]:
    out = []
    for cls in _SECTIONS.values():
        for f in dataclasses.fields(cls):
            if "lo" in f.metadata and not isinstance(f.default, str):
                out.append((cls, f.name))
    return out


def test_every_numeric_field_documents_unit_range_and_source() -> None:
    for cls, name in _ranged_fields():
        meta = field_spec(cls, name)
        assert meta["doc"], f"{cls.__name__}.{name} has no source"
        assert meta["lo"] is not None or meta["hi"] is not None, f"{cls.__name__}.{name}"


def test_defaults_are_valid_and_thesis_is_the_default() -> None:
    assert EnvConfig() == THESIS
    assert set(PRESETS) == {"thesis", "as_built", "as_listed", "ideal", "noisy", "randomized"}
    assert IDEAL.perception.miss_prob == 0.0
    assert IDEAL.perception.latency_frames == 0


@pytest.mark.parametrize(("cls", "name"), _ranged_fields())
def test_a_value_above_the_range_names_field_value_and_range(cls: type, name: str) -> None:
    meta = field_spec(cls, name)
    if meta["hi"] is None:
        pytest.skip("unbounded above")
    bad = meta["hi"] + (1 if meta["integer"] else abs(meta["hi"]) * 0.5 + 1.0)
    with pytest.raises(ValueError, match=rf"{cls.__name__}\.{name}={bad!r} is out of range"):
        cls(**{name: bad})


def test_nan_inf_bool_and_strings_are_rejected() -> None:
    for bad in (math.nan, math.inf, True, "1.0"):
        with pytest.raises(ValueError, match=r"RobotConfig\.wheel_radius_m"):
            RobotConfig(wheel_radius_m=bad)  # type: ignore[arg-type]


def test_integer_fields_refuse_floats() -> None:
    with pytest.raises(ValueError, match=r"an integer in \[0, 8\] frames"):
        PerceptionConfig(latency_frames=1.5)  # type: ignore[arg-type]


def test_open_lower_bounds_exclude_the_bound() -> None:
    with pytest.raises(ValueError, match=r"must be \(0.001, 2\] s"):
        MotorConfig(time_constant_s=0.001)


def test_cross_field_constraints_name_both_fields() -> None:
    with pytest.raises(ValueError, match=r"stall_duty_pct.*friction_duty_pct"):
        MotorConfig(friction_duty_pct=10.0, stall_duty_pct=5.0)
    with pytest.raises(ValueError, match=r"depth_max_m.*depth_min_m"):
        CameraConfig(depth_min_m=2.0, depth_max_m=1.0)
    with pytest.raises(ValueError, match=r"control_dt_s.*whole multiple"):
        THESIS.replace(episode={"control_dt_s": 0.105})


def test_configs_are_frozen() -> None:
    with pytest.raises(dataclasses.FrozenInstanceError):
        THESIS.robot.wheel_radius_m = 1.0  # type: ignore[misc]


def test_derived_platform_limits() -> None:
    # 20 rad/s * 0.075 m * (99 - 4) / (100 - 4)
    platform = THESIS.platform
    assert math.isclose(platform.max_wheel_speed_mps, 20 * 0.075 * 95 / 96)
    assert math.isclose(platform.max_turn_rate_radps, 2 * platform.max_wheel_speed_mps / 0.4)
    assert platform.sub_steps(THESIS.episode.control_dt_s) == 10
