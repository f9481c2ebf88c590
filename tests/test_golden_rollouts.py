"""Behaviour did not change: full rollouts hash to what was recorded, or on another CPU match
its fingerprint (tests/golden/rollouts.py)."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

_spec = importlib.util.spec_from_file_location(
    "golden_rollouts", Path(__file__).parent / "golden" / "rollouts.py"
)
golden = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(golden)  # type: ignore[union-attr]

_DOC = json.loads(golden.GOLDEN.read_text())
RECORDED = _DOC["episodes"]
# Hashes of the same episodes on other CPUs (tests/golden/rollouts.py says when and why).
ALTERNATES = _DOC.get("alternates", {})


@pytest.mark.slow
@pytest.mark.parametrize("case", golden.cases(), ids=lambda case: case.prefix)
def test_single_and_vector_env_replay_the_recorded_episodes(case: Any) -> None:
    lanes = golden.lane_hashes(case, golden.SEEDS)
    for seed, lane_hash in zip(golden.SEEDS, lanes, strict=True):
        name = f"{case.prefix}/{seed}"
        episode = golden.episode_hash(case, seed)
        problem = golden.verdict(name, episode, _DOC)
        assert problem is None, f"{name} single env: {problem}"
        assert lane_hash == episode["sha256"], f"{name} vector lane"


def test_every_case_was_recorded() -> None:
    names = {f"{case.prefix}/{seed}" for case in golden.cases() for seed in golden.SEEDS}
    assert names == set(RECORDED)
    assert set(ALTERNATES) <= names
    # Only a learned agent's episode may end elsewhere on another CPU (golden/rollouts.py).
    moved = {name for name, alts in ALTERNATES.items() for a in alts if "steps" in a}
    assert {golden.policy_of(name) for name in moved} <= set(golden.LEARNED)


def _waypoints_moved(monkeypatch: pytest.MonkeyPatch, by: float | None) -> None:
    """Every person's waypoints moved after each reset: by one unit in the last place (``by``
    None: what another CPU's arithmetic does to a value), or by ``by`` metres (a change)."""
    from follow_env.tasks.person_follow.task import PersonFollowTask

    reset = PersonFollowTask.prepare_reset

    def moved(self: PersonFollowTask, sim: Any, lanes: np.ndarray, keys: np.ndarray) -> Any:
        starts = reset(self, sim, lanes, keys)
        paths = sim.world[1]
        flat = paths.view(np.float64).reshape(*paths.shape, -1)  # the records' fields as floats
        xy = flat[lanes, :, :, 0:2]
        flat[lanes, :, :, 0:2] = np.nextafter(xy, np.inf) if by is None else xy + by
        return starts

    monkeypatch.setattr(PersonFollowTask, "prepare_reset", moved)


def test_the_fingerprint_names_what_differs() -> None:
    want = RECORDED["curve/pn/0"]
    assert golden.verdict("curve/pn/0", dict(want), _DOC) is None
    noise = {**want, "sha256": "0" * 64}
    noise["sums"] = {k: [total * (1 + 1e-13), scale] for k, (total, scale) in want["sums"].items()}
    assert golden.verdict("curve/pn/0", noise, _DOC) is None
    off = {
        **noise,
        "sums": {**noise["sums"], "duty_l_pct": [want["sums"]["duty_l_pct"][0] + 1.0, 1]},
    }
    assert golden.verdict("curve/pn/0", off, _DOC).startswith("duty_l_pct: weighted sum")
    later = {**noise, "steps": want["steps"] + 1}
    assert golden.verdict("curve/pn/0", later, _DOC).startswith("other events")
    flipped = {**noise, "events": "1" * 64}
    assert golden.verdict("curve/pn/0", flipped, _DOC).startswith("other events")


def _start_moved(monkeypatch: pytest.MonkeyPatch, by: float | None) -> None:
    """The line tracer's start pose moved after each reset: by one unit in the last place
    (``by`` None) or by ``by`` metres, as :func:`_waypoints_moved` moves the person's path."""
    from follow_env.tasks.line_trace.task import LineTraceTask

    reset = LineTraceTask.prepare_reset

    def moved(self: LineTraceTask, sim: Any, lanes: np.ndarray, keys: np.ndarray) -> Any:
        pose = reset(self, sim, lanes, keys)
        xy = pose[:, 0:2]
        pose[:, 0:2] = np.nextafter(xy, np.inf) if by is None else xy + by
        return pose

    monkeypatch.setattr(LineTraceTask, "prepare_reset", moved)


def _case(name: str) -> Any:
    """The golden case of episode ``name`` (``<prefix>/<seed>``)."""
    prefix = name.rsplit("/", 1)[0]
    return next(case for case in golden.cases() if case.prefix == prefix)


@pytest.mark.parametrize(
    ("name", "move"),
    [
        ("occlusion/pn/0", _waypoints_moved),
        ("occlusion/ppo/1", _waypoints_moved),
        ("crowd/gsmpn/2", _waypoints_moved),
        ("line:gaps/pid/0", _start_moved),
        ("line:course/coordinate/1", _start_moved),
        ("mecanum:crowd/pn/2", _waypoints_moved),
        ("mecanum:straight/pn/0", _waypoints_moved),  # no bystander: an inf clearance throughout
        ("unicycle:random/gsmpn/1", _waypoints_moved),
        ("line_diff_drive:gaps/pid/2", _start_moved),
    ],
)
def test_last_bits_pass_by_the_fingerprint_and_a_change_does_not(
    name: str, move: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    case, seed = _case(name), int(name.rsplit("/", 1)[1])
    assert golden.verdict(name, golden.episode_hash(case, seed), _DOC) is None
    with monkeypatch.context() as patch:
        move(patch, None)
        last_bits = golden.episode_hash(case, seed)
    assert last_bits["sha256"] != RECORDED[name]["sha256"]  # not bit for bit any more
    assert golden.verdict(name, last_bits, _DOC) is None
    with monkeypatch.context() as patch:
        move(patch, 1e-6)  # a micrometre
        moved = golden.episode_hash(case, seed)
    assert golden.verdict(name, moved, _DOC) is not None


def test_every_task_on_every_platform_has_golden_episodes() -> None:
    # a task or platform added without golden episodes would change unseen
    import gymnasium as gym

    from follow_env.platforms import available_platforms
    from follow_env.tasks import env_ids
    from follow_env.tasks.line_trace.tracks.registry import TRACKS

    own = {}  # each env's own platform, for the cases that name none
    for env_id in env_ids():
        env = gym.make(env_id)
        own[env_id] = env.unwrapped.sim.platform.name
        env.close()
    pinned = {(case.env_id, case.platform or own[case.env_id]) for case in golden.cases()}
    assert pinned == {(e, p) for e in env_ids() for p in available_platforms()}
    # every built-in track (tests register tracks of their own in the same registry)
    builtin = {n for n, spec in TRACKS.items() if spec.fn.__module__.startswith("follow_env.")}
    line = {case.variant for case in golden.cases() if case.prefix.startswith("line:")}
    assert line == builtin == set(golden.LINE_TRACKS)
