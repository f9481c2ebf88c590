"""The light-sensor grid: coverage of a spot by the line, the optics, ambient light, noise."""

from __future__ import annotations

import numpy as np
import pytest

from follow_env.sensors import light_grid
from follow_env.sensors.light_grid import LightGridConfig, cell_positions
from follow_env.tasks.line_trace.config import IDEAL, PAPER
from follow_env.tasks.line_trace.task import TASK, point_along
from follow_env.world.floor_line import LINE_SEGMENT, SEG, line_segments

HALF_W = 0.0095


def _line(points: list[tuple[float, float]], ink: list[float] | None = None) -> np.ndarray:
    flat = line_segments(np.array(points), np.ones(len(points) - 1) if ink is None else ink)
    return flat.view(LINE_SEGMENT.dtype)[:, 0]


def _read(cfg, segs, x=0.0, y=0.0, th=0.0, step=1, key=7):
    prm = light_grid.PARAMS.pack(cfg)
    st = light_grid.STATE.zeros(1)
    keys = np.full(8, key, dtype=np.uint64)
    light_grid.randomize(prm.reshape(1), np.array([0]), cfg, keys.reshape(1, -1))
    light_grid.read(prm[()], st[0], x, y, th, segs, len(segs), HALF_W, keys, step)
    return st[0]


def test_a_line_along_the_heading_covers_the_middle_column_and_crossing_it_the_middle_row() -> None:
    along = _read(IDEAL, _line([(-1.0, 0.0), (1.0, 0.0)]))["cover"].reshape(5, 5)
    assert np.all(along[:, 2] == 1.0)
    across = _read(IDEAL, _line([(0.0, -1.0), (0.0, 1.0)]))["cover"].reshape(5, 5)
    assert np.all(across[2] == 1.0)
    assert across[0].max() == 0.0


def test_a_spot_on_the_lines_edge_is_about_half_covered() -> None:
    # Shift the robot so the column j = 1 (12 mm left) has its centre on the line's edge.
    st = _read(IDEAL, _line([(-1.0, 0.0), (1.0, 0.0)]), y=-(0.012 - HALF_W))
    assert st["cover"].reshape(5, 5)[2, 1] == pytest.approx(0.5, abs=1.5 / 24)


def test_ideal_readings_equal_the_coverage_and_far_cells_read_zero() -> None:
    st = _read(IDEAL, _line([(-1.0, 0.0), (1.0, 0.0)]))
    assert np.array_equal(st["reading"], st["cover"])
    assert st["reading"].reshape(5, 5)[:, [0, 4]].max() == 0.0
    assert st["active"] == 5
    assert st["seen"] == 1.0


def test_a_gap_is_not_read_but_counts_as_line_seen() -> None:
    st = _read(IDEAL, _line([(-1.0, 0.0), (-0.5, 0.0), (0.5, 0.0), (1.0, 0.0)], [1, 0, 1]))
    assert st["reading"].max() == 0.0
    assert st["ink_seen"] == 0.0
    assert st["seen"] == 1.0


def test_ambient_light_pales_the_line() -> None:
    bright = IDEAL.replace(sensor={"ambient_max": 0.5})
    line = _line([(-1.0, 0.0), (1.0, 0.0)])
    assert _read(bright, line)["reading"].reshape(5, 5)[2, 2] < 0.95


def test_a_sensor_mounted_higher_reads_white_floor_darker() -> None:
    high = IDEAL.replace(sensor={"height_m": 0.008})
    st = _read(high, _line([(-1.0, 0.0), (1.0, 0.0)]))
    assert st["reading"].reshape(5, 5)[2, 0] > 0.3


def test_noise_is_a_function_of_key_and_step() -> None:
    line = _line([(-1.0, 0.0), (1.0, 0.0)])
    a, b = _read(PAPER, line, step=3), _read(PAPER, line, step=3)
    c = _read(PAPER, line, step=4)
    assert np.array_equal(a["reading"], b["reading"])
    assert not np.array_equal(a["reading"], c["reading"])


def test_cell_positions_follow_the_spec_order() -> None:
    pos = cell_positions(0.0, 0.0, 0.0, 0.01, 0.0)
    assert pos[0].tolist() == pytest.approx([0.02, 0.02])  # row 0 front, column 0 left
    assert pos[24].tolist() == pytest.approx([-0.02, -0.02])


def test_black_must_be_darker_than_white() -> None:
    with pytest.raises(ValueError, match=r"LightGridConfig\.black_reflectance=0\.9"):
        LightGridConfig(black_reflectance=0.9)


def test_more_segments_near_the_grid_than_its_scratch_list_holds_are_all_read() -> None:
    # 60 short pieces 44 mm to the left (near the grid, touching no spot) come first in the
    # line, then the line under the middle column: it must still be read.
    decoys = _line([(x, 0.044) for x in np.linspace(-0.01, 0.01, 61)])
    line = _line([(-1.0, 0.0), (1.0, 0.0)])
    assert len(decoys) > light_grid.NEAR_MAX
    crowded = _read(IDEAL, np.concatenate([decoys, line]))
    alone = _read(IDEAL, line)
    assert np.array_equal(crowded["cover"], alone["cover"])
    assert np.all(crowded["cover"].reshape(5, 5)[:, 2] == 1.0)
    assert crowded["active"] == 5


def test_small_tiles_under_a_wide_grid_read_every_cell_on_the_line() -> None:
    # The extreme accepted settings (10 cm tiles, a 10 cm pitch): over a hundred segments of
    # the curves track lie near the grid; every cell whose spot lies wholly on the line reads 1.
    cfg = IDEAL.replace(track={"name": "curves", "tile_m": 0.1, "gap_m": 0.05})
    cfg = cfg.replace(sensor={"pitch_m": 0.1})
    track = TASK.fixed_track(cfg)
    segs = track.segments.view(LINE_SEGMENT.dtype)[:, 0]
    half_w, r_spot = 0.5 * cfg.track.line_width_m, 0.5 * cfg.sensor.spot_diameter_m
    most_near, wrong = 0, 0
    for s in np.arange(0.05, track.length_m - 0.1, 0.05):
        x, y, th = point_along(track.segments, s)
        st = _read(cfg, segs, x, y, th)
        centres = np.stack([st["cx"], st["cy"]], axis=1)
        d = _distances(centres, track.segments)
        wrong += int(np.sum((d + r_spot <= half_w - 1e-9) & (st["cover"] < 1.0)))
        reach = 2 * np.sqrt(2) * 0.1 + half_w + r_spot
        near = np.hypot(track.segments[:, SEG.mx] - x, track.segments[:, SEG.my] - y)
        most_near = max(most_near, int(np.sum(near <= 0.5 * track.segments[:, SEG.length] + reach)))
    assert most_near > light_grid.NEAR_MAX  # the case this is about
    assert wrong == 0


def _distances(points: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Each point's distance (m) to the nearest segment of the line (brute force)."""
    a = segments[:, [SEG.x1, SEG.y1]]
    d = segments[:, [SEG.x2, SEG.y2]] - a
    p = points[:, None, :]
    t = np.clip(((p - a) * d).sum(-1) / (d * d).sum(-1), 0.0, 1.0)
    return np.linalg.norm(a + t[..., None] * d - p, axis=-1).min(axis=1)
