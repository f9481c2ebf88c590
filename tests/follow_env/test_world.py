"""Contact geometry: the compiled tests agree with pymunk, which holds the world."""

from __future__ import annotations

import numpy as np

from follow_env.world import (
    WALL_RADIUS_M,
    World,
    rect_rect_distance,
    rect_segment_distance,
    room_walls,
    segment_distance,
)


def test_segment_distance_of_crossing_and_parallel_segments() -> None:
    assert segment_distance(0, 0, 2, 2, 0, 2, 2, 0) == 0.0
    assert np.isclose(segment_distance(0, 0, 1, 0, 0, 1, 1, 1), 1.0)
    assert np.isclose(segment_distance(0, 0, 1, 0, 2, 0, 3, 0), 1.0)


def test_rectangle_to_segment_distance() -> None:
    # A 0.5 x 0.4 rectangle at the origin; a wall 1 m ahead of its centre.
    assert np.isclose(rect_segment_distance(0, 0, 0, 0.5, 0.4, 1, -5, 1, 5), 0.75)
    # Rotated by 90 deg the long side faces sideways: 1 - 0.2.
    assert np.isclose(rect_segment_distance(0, 0, np.pi / 2, 0.5, 0.4, 1, -5, 1, 5), 0.8)
    # A short segment entirely inside the rectangle touches it.
    assert rect_segment_distance(0, 0, 0, 0.5, 0.4, -0.1, 0, 0.1, 0) == 0.0


def test_rectangle_to_rectangle_distance() -> None:
    assert np.isclose(rect_rect_distance(0, 0, 0, 0.5, 0.4, 2, 0, 0, 0.5, 0.4), 1.5)
    assert rect_rect_distance(0, 0, 0, 0.5, 0.4, 0.3, 0.1, 0.7, 0.5, 0.4) == 0.0
    # One inside the other.
    assert rect_rect_distance(0, 0, 0, 2.0, 2.0, 0.1, 0.1, 0.3, 0.2, 0.2) == 0.0


def test_compiled_wall_contact_agrees_with_pymunk() -> None:
    walls = np.vstack([room_walls(6.0, 4.0), [[-1.0, -0.5, 1.0, 0.7]]])
    world = World(walls, 0.5, 0.45)
    rng = np.random.default_rng(0)
    poses = np.column_stack(
        [
            rng.uniform(-3.4, 3.4, 3000),
            rng.uniform(-2.4, 2.4, 3000),
            rng.uniform(-np.pi, np.pi, 3000),
        ]
    )
    disagree, touching = 0, 0
    for x, y, th in poses:
        dist = min(rect_segment_distance(x, y, th, 0.5, 0.45, *w) for w in walls)
        ours = dist < WALL_RADIUS_M
        # Leave out poses within 1 mm of the boundary, where float rounding may go either way.
        if abs(dist - WALL_RADIUS_M) < 1e-3:
            continue
        touching += ours
        disagree += ours != world.robot_touches_wall(x, y, th)
    assert touching > 100  # the sample really exercises contacts
    assert disagree == 0
