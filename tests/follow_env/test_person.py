"""People walk their paths with a human speed profile."""

from __future__ import annotations

import numpy as np

from follow_env.layout import N_PSTATE, PS_DONE, PS_PAUSE, PS_S, PS_TH, PS_V, PS_X, PS_Y
from follow_env.person import person_reset, person_step
from follow_env.scenarios import polyline_paths


def _walk(
    points: list[list[float]], vmax: float, pause: list[float] | None = None, steps: int = 400
) -> np.ndarray:
    pts = np.array([points], dtype=float)
    p = None if pause is None else np.array([pause], dtype=float)
    path = polyline_paths(pts, np.full((1, len(points)), vmax), p)[0]
    ps = np.zeros(N_PSTATE)
    person_reset(ps, path, len(points))
    log = []
    for _ in range(steps):
        person_step(ps, path, 0.5, 0.8, 0.1)
        log.append(ps.copy())
    return np.array(log)


def test_a_person_starts_from_rest_and_reaches_cruise_pace() -> None:
    log = _walk([[0, 0], [10, 0]], 1.0)
    assert np.isclose(log[0, PS_V], 0.05)  # 0.5 m/s^2 for 0.1 s
    assert np.isclose(log[:, PS_V].max(), 1.0)
    assert np.all(np.diff(log[:20, PS_V]) >= 0)


def test_a_person_stops_at_the_end_of_the_path_at_rest() -> None:
    log = _walk([[0, 0], [10, 0]], 1.0)
    assert log[-1, PS_DONE] == 1.0
    assert np.isclose(log[-1, PS_X], 10.0)
    assert log[-1, PS_V] == 0.0
    # Braking at 0.8 m/s^2: from 1 m/s that is about 1.25 s, never a jump to zero from cruise.
    done = int(np.argmax(log[:, PS_DONE]))
    assert log[done - 1, PS_V] < 0.2


def test_a_person_pauses_at_a_stop_waypoint() -> None:
    log = _walk([[0, 0], [3, 0], [6, 0]], 1.0, pause=[0, 2.0, 0])
    paused = log[:, PS_PAUSE] > 0
    assert paused.any()
    assert np.allclose(log[paused, PS_X], 3.0)
    assert 18 <= paused.sum() <= 21  # 2 s at 0.1 s a step
    assert log[-1, PS_DONE] == 1.0


def test_a_person_faces_along_the_leg() -> None:
    log = _walk([[0, 0], [0, 5]], 1.0, steps=10)
    assert np.allclose(log[:, PS_TH], np.pi / 2)
    assert np.all(np.diff(log[:, PS_Y]) > 0)
    assert np.allclose(log[:, PS_S], log[:, PS_Y])
