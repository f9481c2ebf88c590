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

_DOC = json.loads(golden.GOLDEN.read_text())
RECORDED = _DOC["episodes"]
# Hashes of the same episodes on other CPUs (tests/golden/rollouts.py says when and why).
ALTERNATES = _DOC.get("alternates", {})


@pytest.mark.slow
@pytest.mark.parametrize(("prefix", "scenario", "policy", "config"), golden.cases())
def test_single_and_vector_env_replay_the_recorded_episodes(
    prefix: str, scenario: str, policy: str, config: object
) -> None:
    lanes = golden.vector_env_hashes(scenario, golden.SEEDS, policy, config)
    for seed, lane_hash in zip(golden.SEEDS, lanes, strict=True):
        name = f"{prefix}/{seed}"
        digest, steps = golden.single_env_hash(scenario, seed, policy, config)
        assert (digest, steps) in golden.accepted(name, _DOC), f"{name} single env"
        assert lane_hash == digest, f"{name} vector lane"


def test_every_case_was_recorded() -> None:
    names = {f"{prefix}/{seed}" for prefix, *_ in golden.cases() for seed in golden.SEEDS}
    assert names == set(RECORDED)
    assert set(ALTERNATES) <= names
    # Only a learned agent's episode may end elsewhere on another CPU (golden/rollouts.py).
    moved = {name for name, alts in ALTERNATES.items() for a in alts if "steps" in a}
    assert {golden.policy_of(name) for name in moved} <= set(golden.LEARNED)
