"""People walk their paths with a human speed profile."""

from __future__ import annotations

import numpy as np
from numba import njit

from follow_env.tasks.person_follow.people import PERSON, as_waypoints, person_reset, person_step
from follow_env.tasks.person_follow.scenarios import polyline_paths


@njit
def _start(people: np.ndarray, path: np.ndarray, n_points: int) -> None:
    person_reset(people[0], path, n_points)


@njit
def _step(people: np.ndarray, path: np.ndarray) -> None:
    person_step(people[0], path, 0.5, 0.8, 0.1)


def _walk(
    points: list[list[float]], vmax: float, pause: list[float] | None = None, steps: int = 400
) -> np.ndarray:
    pts = np.array([points], dtype=float)
    p = None if pause is None else np.array([pause], dtype=float)
    path = as_waypoints(polyline_paths(pts, np.full((1, len(points)), vmax), p)[0])
    people = PERSON.zeros(1)
    _start(people, path, len(points))
    log = PERSON.zeros(steps)
    for k in range(steps):
        _step(people, path)
        log[k] = people[0]
    return log


def test_a_person_starts_from_rest_and_reaches_cruise_pace() -> None:
    log = _walk([[0, 0], [10, 0]], 1.0)
    assert np.isclose(log["v"][0], 0.05)  # 0.5 m/s^2 for 0.1 s
    assert np.isclose(log["v"][:].max(), 1.0)
    assert np.all(np.diff(log["v"][:20]) >= 0)


def test_a_person_stops_at_the_end_of_the_path_at_rest() -> None:
    log = _walk([[0, 0], [10, 0]], 1.0)
    assert log["done"][-1] == 1.0
    assert np.isclose(log["x"][-1], 10.0)
    assert log["v"][-1] == 0.0
    # Braking at 0.8 m/s^2: from 1 m/s that is about 1.25 s, never a jump to zero from cruise.
    done = int(np.argmax(log["done"][:]))
    assert log["v"][done - 1] < 0.2


def test_a_person_pauses_at_a_stop_waypoint() -> None:
    log = _walk([[0, 0], [3, 0], [6, 0]], 1.0, pause=[0, 2.0, 0])
    paused = log["pause"][:] > 0
    assert paused.any()
    assert np.allclose(log["x"][paused], 3.0)
    assert 18 <= paused.sum() <= 21  # 2 s at 0.1 s a step
    assert log["done"][-1] == 1.0


def test_a_person_faces_along_the_leg() -> None:
    log = _walk([[0, 0], [0, 5]], 1.0, steps=10)
    assert np.allclose(log["th"][:], np.pi / 2)
    assert np.all(np.diff(log["y"][:]) > 0)
    assert np.allclose(log["s"][:], log["y"][:])
