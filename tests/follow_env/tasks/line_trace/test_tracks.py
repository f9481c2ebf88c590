"""Tracks: tile programs laid as lines, the built-in courses, the random one per seed."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import follow_env  # noqa: F401  (registers the envs)
from follow_env.tasks.line_trace.config import PAPER
from follow_env.tasks.line_trace.tracks import (
    TRACKS,
    TrackLayout,
    build_track,
    get_track,
    lay,
    register_track,
    tile_cells,
)
from follow_env.tasks.line_trace.tracks.builtin import FIXED_PROGRAMS
from follow_env.world.floor_line import SEG

T = PAPER.track.tile_m


def _track(program: str):
    return build_track("t", TrackLayout(program), PAPER)


@pytest.mark.parametrize("name", sorted(FIXED_PROGRAMS))
def test_every_fixed_track_is_one_continuous_line_inside_its_field(name: str) -> None:
    track = lay(get_track(name), np.zeros(1, np.uint64), PAPER)
    seg = track.segments
    ends = seg[:-1, [SEG.x2, SEG.y2]]
    starts = seg[1:, [SEG.x1, SEG.y1]]
    assert np.allclose(ends, starts)
    assert np.allclose(seg[1:, SEG.s], seg[:-1, SEG.s] + seg[:-1, SEG.length])
    assert track.length_m == pytest.approx(seg[:, SEG.length].sum())
    x0, y0, x1, y1 = track.field
    pts = seg[:, [SEG.x1, SEG.y1, SEG.x2, SEG.y2]].reshape(-1, 2)
    assert pts[:, 0].min() >= x0 + T - 1e-9
    assert pts[:, 0].max() <= x1 - T + 1e-9
    assert pts[:, 1].min() >= y0 + T - 1e-9
    assert pts[:, 1].max() <= y1 - T + 1e-9
    assert len(seg) <= get_track(name).segments_for(PAPER)


def test_tiles_have_their_lengths() -> None:
    assert _track("S").length_m == pytest.approx(T)
    assert _track("L").length_m == pytest.approx(T)  # two half tiles
    # A quarter circle of half a tile's radius (chords: 0.1 % short at most).
    assert _track("l").length_m == pytest.approx(math.pi * T / 4, rel=1e-3)
    zig = PAPER.track
    tooth = math.hypot(T / zig.zigzag_teeth, 2 * zig.zigzag_amplitude_m)
    edge = math.hypot(0.5 * T / zig.zigzag_teeth, zig.zigzag_amplitude_m)
    expected = 2 * edge + (zig.zigzag_teeth - 1) * tooth
    assert _track("Z").length_m == pytest.approx(expected)


def test_a_gap_tile_leaves_out_gap_m_of_line() -> None:
    seg = _track("G").segments
    assert seg[:, SEG.ink].tolist() == [1.0, 0.0, 1.0]
    assert seg[1, SEG.length] == pytest.approx(PAPER.track.gap_m)


def test_turns_leave_to_their_side() -> None:
    for letter, dy in (("L", 1), ("l", 1), ("R", -1), ("r", -1)):
        cells, _ = tile_cells(letter + "S")
        assert cells[1].tolist() == [0, dy]


def test_bad_programs_are_refused() -> None:
    with pytest.raises(ValueError, match="is not one of"):
        tile_cells("SX")
    with pytest.raises(ValueError, match="lies on an earlier tile"):
        tile_cells("LLLLS")


def _random(key: int):
    return lay(get_track("random"), np.array([key], np.uint64), PAPER)


def test_the_random_track_is_a_function_of_the_key() -> None:
    assert _random(5).program == _random(5).program
    programs = {_random(k).program for k in range(10)}
    assert len(programs) == 10


def test_random_tracks_keep_to_their_field_and_start_and_end_plain() -> None:
    tc = PAPER.track
    for k in range(20):
        track = _random(k)
        assert len(track.program) == tc.random_tiles
        assert track.program[0] == "S"
        assert track.program[-1] == "S"
        span = track.cells.max(axis=0) - track.cells.min(axis=0) + 1
        assert span[0] <= tc.random_cols
        assert span[1] <= tc.random_rows
        assert len({tuple(c) for c in track.cells}) == len(track.cells)


def test_the_random_track_changes_with_the_seed_in_the_env() -> None:
    env = gym.make("LineTrace-v0", track="random")
    lengths = set()
    for seed in range(4):
        _, info = env.reset(seed=seed)
        lengths.add(round(info["track_length_m"], 6))
    assert len(lengths) > 1


def test_a_registered_track_runs_in_the_env() -> None:
    if "hook_test" not in TRACKS:
        register_track("hook_test", max_tiles=5)(lambda rng, cfg: TrackLayout("SSlGr"))
    env = gym.make("LineTrace-v0", track="hook_test")
    _, info = env.reset(seed=0)
    assert info["track_length_m"] == pytest.approx(3 * T + 2 * math.pi * T / 4, rel=1e-3)


def test_a_start_past_the_shortest_random_track_is_refused_when_the_env_is_made() -> None:
    # Two tiles make a 0.6 m line whatever is drawn: a start 1 m along it used to be accepted,
    # reported progress 1.0 at reset and paid the finish bonus on the first step.
    with pytest.raises(
        ValueError,
        match=r"StartConfig\.distance_m=1\.0 is out of range: must be < the shortest 'random' "
        r"track's length less finish_margin_m \(0\.600 - 0\.02 = 0\.580 m\)",
    ):
        gym.make("LineTrace-v0", track={"name": "random", "random_tiles": 2}, start__distance_m=1.0)
    env = gym.make(
        "LineTrace-v0", track={"name": "random", "random_tiles": 2}, start__distance_m=0.5
    )
    _, info = env.reset(seed=0)
    assert info["progress_m"] == pytest.approx(0.5)
    assert info["track_length_m"] == pytest.approx(0.6)


@pytest.mark.parametrize("curve_prob", [0.0, 0.5, 1.0])
def test_the_shortest_random_track_bounds_every_random_track(curve_prob: float) -> None:
    cfg = PAPER.replace(track={"random_tiles": 6, "random_curve_prob": curve_prob})
    shortest = get_track("random").shortest(cfg)
    lengths = [lay(get_track("random"), np.array([k], np.uint64), cfg).length_m for k in range(40)]
    assert min(lengths) >= shortest - 1e-12
    straight = cfg.replace(track={"random_tiles": 2})
    assert get_track("random").shortest(straight) == pytest.approx(2 * T)


def test_a_random_track_laid_shorter_than_the_start_is_refused_at_reset() -> None:
    # A track of one's own that does not say how short it may be: refused when laid.
    if "short_or_long_test" not in TRACKS:

        def short_or_long(rng, cfg):
            return TrackLayout("SS" if rng.uniform()[0] < 0.5 else "SSSS")

        register_track("short_or_long_test", max_tiles=4, random=True)(short_or_long)
    env = gym.make("LineTrace-v0", track="short_or_long_test", start__distance_m=0.9)
    refusals, lengths = [], set()
    for seed in range(12):
        try:
            _, info = env.reset(seed=seed)
        except ValueError as err:
            refusals.append(str(err))
        else:
            assert info["progress_m"] < info["track_length_m"]
            lengths.add(round(info["track_length_m"], 6))
    assert refusals  # met both kinds of track
    assert lengths == {1.2}
    for message in refusals:
        assert "StartConfig.distance_m=0.9 is out of range" in message
        assert "the length of the 'short_or_long_test' track laid" in message


def test_a_random_field_fuller_than_three_quarters_is_refused_and_the_fullest_lays_fast() -> None:
    # A full 20 x 3 field took 22 s a reset and then found no track; a full 8 x 6 one 2-12 s.
    with pytest.raises(
        ValueError, match=r"TrackConfig.random_tiles=60 is out of range: must be <= 3/4 of"
    ):
        PAPER.replace(track={"random_tiles": 60, "random_cols": 20, "random_rows": 3})
    cfg = PAPER.replace(track={"random_tiles": 45, "random_cols": 20, "random_rows": 3})
    for key in range(3):
        assert len(lay(get_track("random"), np.array([key], np.uint64), cfg).program) == 45
