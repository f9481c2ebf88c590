"""JumpGate: the agent's own data association holds off a reading that jumps further in a step
than a person can walk, and takes it when it persists."""

from __future__ import annotations

import numpy as np
import pytest

from policies.learned.features import FEATURES, Box, ObservationAge, Pipeline
from policies.learned.gate import JumpGate

OBS = Box(np.array([0.0, -640.0, 0.0]), np.array([10.0, 640.0, 10.0]))
ACT = Box(-np.ones(2), np.ones(2))


def gate(n: int = 1, **kwargs: object) -> JumpGate:
    step = JumpGate(**kwargs)  # type: ignore[arg-type]
    step.bind(OBS, ACT, n)
    return step


def rows(*obs: tuple[float, float, float]) -> np.ndarray:
    return np.array(obs, dtype=np.float32)


def run(step: JumpGate, readings: list[tuple[float, float, float]]) -> np.ndarray:
    out = [step.start(rows(readings[0]))[0]]
    for reading in readings[1:]:
        out.append(step.observe(rows(reading), np.zeros(1, dtype=bool))[0])
    return np.array(out)


def test_a_bystander_taking_the_persons_place_is_held_off_until_the_person_is_back() -> None:
    # the crowd handoff: the filtered distance climbs a metre a frame to a bystander 5 m away,
    # then the person (1.0 m) is detected first again; the reading ahead passes untouched
    readings = [(1.06, -30, 1.1), (1.94, 306, 1.1), (2.84, 312, 1.0), (5.1, 299, 0.9),
                (1.02, -20, 1.0), (1.0, -10, 1.0)]  # fmt: skip
    out = run(gate(max_jump_m=0.5, accept_after=10), readings)
    np.testing.assert_array_equal(out[:4, :2], np.tile(np.float32([1.06, -30]), (4, 1)))
    np.testing.assert_array_equal(out[:, 2], np.float32([1.1, 1.1, 1.0, 0.9, 1.0, 1.0]))
    np.testing.assert_array_equal(out[4:, :2], np.float32([[1.02, -20], [1.0, -10]]))


def test_a_reading_detected_afresh_accept_after_times_is_taken() -> None:
    readings = [(1.0, 0, 1), (3.0, 50, 1), (3.02, 52, 1), (3.04, 54, 1), (3.06, 56, 1)]
    out = run(gate(max_jump_m=0.5, accept_after=2), readings)
    np.testing.assert_array_equal(out[:, 0], np.float32([1.0, 1.0, 1.0, 3.04, 3.06]))
    # then the gate starts again from the new reading: a jump back is held off anew
    out = run(gate(max_jump_m=0.5, accept_after=2), [*readings, (1.0, 0, 1)])
    assert out[-1, 0] == np.float32(3.06)


def test_a_reading_the_perception_repeats_through_a_detection_gap_is_never_taken() -> None:
    # a bystander's reading, held by the perception while the detector sees nobody, then the
    # person detected again near where they were last seen
    readings = [(1.0, 0, 1), (1.9, 310, 1)] + [(1.9, 310, 1)] * 15 + [(1.04, 20, 1)]
    out = run(gate(max_jump_m=0.5, accept_after=2), readings)
    np.testing.assert_array_equal(out[:-1, :2], np.tile(np.float32([1.0, 0]), (17, 1)))
    np.testing.assert_array_equal(out[-1, :2], np.float32([1.04, 20]))


def test_the_offset_gate_and_what_is_never_gated() -> None:
    step = gate(max_jump_m=None, max_jump_px=100.0, accept_after=5)
    out = run(step, [(1.0, 0, 1), (1.05, 90, 1), (1.05, 250, 1), (1.8, 80, 1)])
    np.testing.assert_array_equal(out[:, :2], np.float32([[1, 0], [1.05, 90], [1.05, 90],
                                                          [1.8, 80]]))  # fmt: skip
    # no reading yet (distance 0) before or after: nothing to compare, nothing held
    out = run(gate(max_jump_m=0.5), [(0.0, 0, 1), (2.0, 10, 1), (0.0, 0, 1), (1.0, 5, 1)])
    np.testing.assert_array_equal(out[:, 0], np.float32([0.0, 2.0, 0.0, 1.0]))


def test_lanes_are_independent_and_a_new_episode_starts_afresh() -> None:
    step = gate(n=2, max_jump_m=0.5, accept_after=10)
    step.start(rows((1.0, 0, 1), (1.0, 0, 1)))
    out = step.observe(rows((4.0, 0, 1), (4.0, 0, 1)), np.array([False, True]))
    np.testing.assert_array_equal(out[:, 0], np.float32([1.0, 4.0]))  # lane 1 was just reset
    # the terminal view of lane 0 is gated as observe would gate it, and changes nothing
    np.testing.assert_array_equal(step.terminal(np.float32([5.0, 9, 1]), 0), [1.0, 0, 1])
    np.testing.assert_array_equal(
        step.terminal(np.float32([1.2, 9, 1]), 0), np.float32([1.2, 9, 1])
    )
    out = step.observe(rows((1.1, 0, 1), (4.1, 0, 1)), np.zeros(2, dtype=bool))
    np.testing.assert_array_equal(out[:, 0], np.float32([1.1, 4.1]))


def test_a_held_off_reading_counts_as_stale_for_the_age() -> None:
    """Behind the gate, :class:`ObservationAge` sees the held detection repeat, as when the
    detector sees nobody: the agent knows its reading is old."""
    pipeline = Pipeline(
        [JumpGate(max_jump_m=0.5), ObservationAge(max_age_steps=10, entries=2)], OBS, ACT, 1
    )
    ages = [pipeline.start(rows((1.0, 0, 1)))[0, -1]]
    for reading in ((1.1, 5, 1), (3.0, 200, 1), (3.5, 210, 1), (1.15, 8, 1)):
        ages.append(pipeline.observe(rows(reading))[0, -1])
    np.testing.assert_allclose(ages, [0.0, 0.0, 0.1, 0.2, 0.0])
    assert FEATURES["JumpGate"] is JumpGate


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"max_jump_m": 0.0}, r"JumpGate\.max_jump_m=0\.0 is out of range"),
        ({"max_jump_px": -5}, r"JumpGate\.max_jump_px=-5 is out of range"),
        ({"accept_after": 0}, r"JumpGate\.accept_after=0 is out of range"),
        ({"accept_after": 2.5}, r"JumpGate\.accept_after=2\.5 is out of range"),
    ],
)
def test_bad_arguments_are_refused_naming_them(kwargs: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        gate(**kwargs)
    with pytest.raises(ValueError, match=r"JumpGate needs \[distance_m, offset_px, \.\.\.\]"):
        JumpGate().bind(Box(np.zeros(1), np.ones(1)), ACT, 1)
