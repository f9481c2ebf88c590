"""Behaviour did not change: full rollouts hash to what was recorded (tests/golden/)."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

_spec = importlib.util.spec_from_file_location(
    "golden_rollouts", Path(__file__).parent / "golden" / "rollouts.py"
)
golden = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(golden)  # type: ignore[union-attr]

RECORDED = json.loads(golden.GOLDEN.read_text())["episodes"]


@pytest.mark.slow
@pytest.mark.parametrize(("prefix", "scenario", "policy", "config"), golden.cases())
def test_single_and_vector_env_replay_the_recorded_episodes(
    prefix: str, scenario: str, policy: str, config: object
) -> None:
    lanes = golden.vector_env_hashes(scenario, golden.SEEDS, policy, config)
    for seed, lane_hash in zip(golden.SEEDS, lanes, strict=True):
        want = RECORDED[f"{prefix}/{seed}"]
        digest, steps = golden.single_env_hash(scenario, seed, policy, config)
        assert (digest, steps) == (want["sha256"], want["steps"]), f"{prefix}/{seed} single env"
        assert lane_hash == want["sha256"], f"{prefix}/{seed} vector lane"


def test_every_case_was_recorded() -> None:
    names = {f"{prefix}/{seed}" for prefix, *_ in golden.cases() for seed in golden.SEEDS}
    assert names == set(RECORDED)
