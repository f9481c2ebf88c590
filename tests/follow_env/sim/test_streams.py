"""The one randomness table: no two draws can share a (key, counter)."""

from __future__ import annotations

import importlib
import pkgutil

import pytest

import follow_env
from follow_env.sim import streams


def _import_everything() -> None:
    for info in pkgutil.walk_packages(follow_env.__path__, prefix="follow_env."):
        importlib.import_module(info.name)


def test_no_two_allocations_of_the_whole_package_overlap() -> None:
    _import_everything()
    names = {a.name for a in streams.ALLOCATIONS}
    # Every kind of draw the package makes is declared in the table.
    for expected in (
        "detector.person",
        "detector.appearance",
        "depth.noise",
        "platform.push",
        "platform.encoder_noise",
        "platform.motor_gains",
        "platform.geometry_error",
        "camera.tilt",
        "scenario.person",
        "scenario.world",
    ):
        assert expected in names
    streams.check_table()


def test_every_derived_key_has_its_own_constant() -> None:
    _import_everything()
    constants = [k.constant for k in streams.KEYS if isinstance(k, streams.Domain)]
    assert len(constants) == len(set(constants))
    assert len(constants) >= 5


def test_an_overlapping_allocation_is_refused_at_once() -> None:
    _import_everything()
    with pytest.raises(ValueError, match=r"overlaps 'detector\.person'"):
        streams.per_step("test.clash", streams.DETECTOR, 100, 2)
    assert "test.clash" not in {a.name for a in streams.ALLOCATIONS}


def test_per_episode_draws_cannot_reach_back_into_per_step_counters() -> None:
    with pytest.raises(ValueError, match="reaches the per-episode counters"):
        streams.per_step("test.huge", streams.WORLD, 0, 1, stride=10**7)


def test_a_second_open_ended_allocation_on_one_key_is_refused() -> None:
    _import_everything()
    with pytest.raises(ValueError, match=r"overlaps 'scenario\.world'"):
        streams.per_episode("test.open", streams.WORLD, 5, None)


def test_a_domain_constant_may_not_be_reused() -> None:
    _import_everything()
    detector_domain = next(k for k in streams.KEYS if isinstance(k, streams.Domain))
    with pytest.raises(ValueError, match="clashes"):
        streams.domain("test.domain", streams.DEPTH, detector_domain.constant, "a copy")
