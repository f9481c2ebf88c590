"""Line of sight (follow_env/world/sight.py) and the camera's use of it (sensors/camera.py): a
list of occluders that overflows its array is detected and every occluder tested instead."""

from __future__ import annotations

import math

import numpy as np

from follow_env.sensors.camera import PARAMS as CAMERA_PARAMS
from follow_env.sensors.camera import sight_box
from follow_env.tasks.person_follow.config import THESIS
from follow_env.tasks.person_follow.task import N_OCCLUDERS
from follow_env.world.geometry import as_wall_records, polygon_walls
from follow_env.world.sight import list_occluders, list_people, sight_blocked, sight_blocked_by_any

PEOPLE = np.dtype([("x", "f8"), ("y", "f8")])
RADIUS_M, HEIGHT_M = 0.2, 1.8  # every person's (m)


def _pillar(sides: int = 72) -> np.ndarray:
    """A round pillar of radius 0.15 m at (3, 0) drawn as a polygon of 5 deg sides (as
    floor_line.arc_points draws arcs), 3 m tall: WALL records."""
    corners = [
        (3.0 + 0.15 * math.cos(2 * math.pi * k / sides), 0.15 * math.sin(2 * math.pi * k / sides))
        for k in range(sides)
    ]
    return as_wall_records(polygon_walls(corners, 3.0))


def _through_the_rim() -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """An eye and a point whose sight line cuts the pillar's rim between 326 and 354 deg: only
    sides past the 64th (65 and 70) stand in it."""
    a, b = math.radians(326.0), math.radians(354.0)
    p1 = np.array([3.0 + 0.15 * math.cos(a), 0.15 * math.sin(a)])
    p2 = np.array([3.0 + 0.15 * math.cos(b), 0.15 * math.sin(b)])
    d = (p2 - p1) / np.linalg.norm(p2 - p1)
    eye, point = p1 - 3.0 * d, p2 + 1.0 * d
    return (eye[0], eye[1], 1.0), (point[0], point[1], 1.0)


def test_the_occluder_list_counts_what_does_not_fit_so_the_overflow_shows() -> None:
    walls = _pillar()
    eye, point = _through_the_rim()
    short = np.zeros(N_OCCLUDERS, dtype=np.int64)
    n = list_occluders(eye[0], eye[1], point[0], point[1], 0.325, walls, len(walls), short)
    room = np.zeros(128, dtype=np.int64)
    n_all = list_occluders(eye[0], eye[1], point[0], point[1], 0.325, walls, len(walls), room)
    assert n == n_all == 72 > N_OCCLUDERS  # every side is near; the count says so
    assert np.array_equal(short, room[:N_OCCLUDERS])  # written as far as there is room
    people = np.zeros(3, dtype=PEOPLE)
    people["x"] = 3.0  # all three on the sight line's way
    m = list_people(eye[0], eye[1], point[0], point[1], 1.0, 1, people, 3, short, n)
    assert m == n + 2  # counted, not written, past the end; person 1 skipped


def test_an_overflowing_list_is_read_only_as_far_as_it_holds() -> None:
    walls = _pillar()
    eye, point = _through_the_rim()
    cand = np.zeros(N_OCCLUDERS, dtype=np.int64)
    n = list_occluders(eye[0], eye[1], point[0], point[1], 0.325, walls, len(walls), cand)
    people = np.zeros(0, dtype=PEOPLE)
    # Reads cand[:64] only (none of them in the way), never past its end.
    assert not sight_blocked(*eye, *point, cand, n, walls, people, RADIUS_M, HEIGHT_M)


def test_testing_every_occluder_finds_the_sides_past_the_list() -> None:
    walls = _pillar()
    eye, point = _through_the_rim()
    people = np.zeros(0, dtype=PEOPLE)
    assert sight_blocked_by_any(*eye, *point, walls, len(walls), people, 0, -1, RADIUS_M, HEIGHT_M)
    room = np.zeros(128, dtype=np.int64)
    n = list_occluders(eye[0], eye[1], point[0], point[1], 0.325, walls, len(walls), room)
    assert sight_blocked(*eye, *point, room, n, walls, people, RADIUS_M, HEIGHT_M)


def test_every_person_but_the_skipped_one_is_tested_when_the_list_overflowed() -> None:
    walls = as_wall_records(np.zeros((0, 5)))
    people = np.zeros(2, dtype=PEOPLE)
    people[0] = (2.0, 0.0)  # the person looked at (skipped), then one in the way
    people[1] = (1.0, 0.0)
    eye, point = (0.0, 0.0, 1.0), (2.0, 0.0, 1.0)
    assert sight_blocked_by_any(*eye, *point, walls, 0, people, 2, 0, RADIUS_M, HEIGHT_M)
    assert not sight_blocked_by_any(*eye, *point, walls, 0, people, 2, 1, RADIUS_M, HEIGHT_M)


def test_the_camera_does_not_see_a_person_behind_a_wall_past_the_occluder_list() -> None:
    # 64 short walls just behind the person (near the sight line, hiding nothing), then one
    # wall across the sight line: the list holds the 64 first; the person must still be hidden.
    decoys = [(4.3, -0.1 + 0.003 * k, 4.3, -0.098 + 0.003 * k, 3.0) for k in range(N_OCCLUDERS)]
    walls = as_wall_records(np.array([*decoys, (2.0, -1.0, 2.0, 1.0, 3.0)]))
    people = np.zeros(1, dtype=PEOPLE)
    people[0] = (4.0, 0.0)
    cam = CAMERA_PARAMS.pack(THESIS)[()]
    box = (200.0, 100.0, 440.0, 400.0)  # the body's box in the image (px); inside it
    body = (THESIS.person.width_m, THESIS.person.depth_m, THESIS.person.height_m)
    pose = (0.0, 0.0, 1.0, 0.0, float(cam["T"][0]), float(cam["T"][1]))
    cand = np.zeros(N_OCCLUDERS, dtype=np.int64)
    share, *_ = sight_box(0, 1.0, box, box, pose, cam, people, 1, walls, len(walls), body, cand)
    assert share == 0.0
    # The same wall alone fits the list, and hides the person the same way.
    alone = walls[N_OCCLUDERS:]
    share, *_ = sight_box(0, 1.0, box, box, pose, cam, people, 1, alone, 1, body, cand)
    assert share == 0.0
