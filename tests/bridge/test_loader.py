"""bridge/loader.py: a mode's policy is built in a thread of its own."""

from __future__ import annotations

import threading
import time
from typing import Any

import pytest

from bridge.loader import PolicyLoader


def _wait(loader: PolicyLoader, mode: str) -> Any:
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline:
        built = loader.get(mode)
        if built is not None:
            return built
        time.sleep(0.01)
    raise AssertionError(f"{mode} was not built in 10 s")


def test_a_policy_is_none_while_it_is_built_then_handed_over_once() -> None:
    gate = threading.Event()
    calls: list[str] = []

    def factory(mode: str) -> str:
        calls.append(mode)
        gate.wait(10.0)
        return f"policy {mode}"

    loader = PolicyLoader(factory, lambda p: p)
    assert loader.get("ppo") is None  # starts building
    assert loader.pending == ["ppo"]
    assert loader.get("ppo") is None  # still building: not started twice
    gate.set()
    assert _wait(loader, "ppo") == "policy ppo"
    assert loader.pending == []
    assert calls == ["ppo"]
    loader.close()


def test_a_policy_the_check_refuses_raises_once_when_built() -> None:
    def check(policy: str) -> str:
        raise ValueError(f"{policy} needs what this robot lacks")

    loader = PolicyLoader(lambda mode: mode, check)
    with pytest.raises(ValueError, match=r"^ppo_ahead needs what this robot lacks$"):
        _wait(loader, "ppo_ahead")
    assert loader.pending == []  # asked again, it is tried again
    assert loader.get("ppo_ahead") is None
    loader.close()
    assert loader.pending == []


def test_close_drops_the_modes_not_started() -> None:
    gate, done = threading.Event(), threading.Event()
    built: list[str] = []

    def factory(mode: str) -> str:
        gate.wait(10.0)
        built.append(mode)
        done.set()
        return mode

    loader = PolicyLoader(factory, lambda p: p)
    loader.get("ppo")
    loader.get("ppo_ahead")  # queued behind ppo: one is built at a time
    assert loader.pending == ["ppo", "ppo_ahead"]
    loader.close()
    gate.set()
    assert done.wait(10.0)
    time.sleep(0.1)  # time for a queued build to start, were it not dropped
    assert built == ["ppo"]  # the one under way finished unused; the queued one never ran
