"""Contact geometry: the compiled tests agree with pymunk, which holds the world."""

from __future__ import annotations

import numpy as np

from follow_env.world.geometry import (
    WALL_RADIUS_M,
    World,
    rect_rect_distance,
    rect_segment_distance,
    room_walls,
)


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


def test_rectangle_distance_agrees_with_brute_force_sampling() -> None:
    rng = np.random.default_rng(1)
    for _ in range(200):
        r1 = (*rng.uniform(-1, 1, 2), rng.uniform(-np.pi, np.pi), *rng.uniform(0.2, 1.0, 2))
        r2 = (*rng.uniform(-1, 1, 2), rng.uniform(-np.pi, np.pi), *rng.uniform(0.2, 1.0, 2))
        d = rect_rect_distance(*r1, *r2)
        # Sample both outlines densely; the sampled distance bounds the true one from above.
        p1, p2 = _outline(*r1), _outline(*r2)
        sampled = np.min(np.linalg.norm(p1[:, None] - p2[None], axis=-1))
        overlap = _inside(p1, *r2).any() or _inside(p2, *r1).any()
        if overlap:
            assert d == 0.0
        else:
            assert d <= sampled + 1e-9
            assert sampled - d < 0.01  # within the sampling step


def _outline(cx: float, cy: float, th: float, length: float, width: float) -> np.ndarray:
    t = np.linspace(0, 1, 100, endpoint=False)
    hl, hw = length / 2, width / 2
    local = np.concatenate(
        [
            np.column_stack([-hl + 2 * hl * t, np.full_like(t, -hw)]),
            np.column_stack([np.full_like(t, hl), -hw + 2 * hw * t]),
            np.column_stack([hl - 2 * hl * t, np.full_like(t, hw)]),
            np.column_stack([np.full_like(t, -hl), hw - 2 * hw * t]),
        ]
    )
    c, s = np.cos(th), np.sin(th)
    return local @ np.array([[c, s], [-s, c]]) + [cx, cy]


def _inside(
    points: np.ndarray, cx: float, cy: float, th: float, length: float, width: float
) -> np.ndarray:
    c, s = np.cos(th), np.sin(th)
    d = points - [cx, cy]
    return (np.abs(d @ [c, s]) <= length / 2) & (np.abs(d @ [-s, c]) <= width / 2)


def test_compiled_wall_contact_agrees_with_pymunk() -> None:
    walls = np.vstack([room_walls(6.0, 4.0), [[-1.0, -0.5, 1.0, 0.7, 1.0]]])
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
        dist = min(rect_segment_distance(x, y, th, 0.5, 0.45, *w[:4]) for w in walls)
        ours = dist < WALL_RADIUS_M
        # Leave out poses within 1 mm of the boundary, where float rounding may go either way.
        if abs(dist - WALL_RADIUS_M) < 1e-3:
            continue
        touching += ours
        disagree += ours != world.robot_touches_wall(x, y, th)
    assert touching > 100  # the sample really exercises contacts
    assert disagree == 0
