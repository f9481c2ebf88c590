"""bridge/loader.py: a mode's policy is built in a thread of its own."""

from __future__ import annotations

import threading
import time
from typing import Any

import pytest

from bridge.loader import MAX_BUILDS, PolicyLoader


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


def test_a_mode_built_and_not_claimed_is_no_longer_pending() -> None:
    # the robot's monitor shows the pending modes: one given up (STOP) showed "loading" for ever
    gate = threading.Event()

    def factory(mode: str) -> str:
        gate.wait(10.0)
        return f"policy {mode}"

    loader = PolicyLoader(factory, lambda p: p)
    assert loader.get("mpn") is None
    assert loader.pending == ["mpn"]
    gate.set()
    deadline = time.monotonic() + 10.0
    while loader.pending and time.monotonic() < deadline:
        time.sleep(0.01)
    assert loader.pending == []
    assert loader.get("mpn") == "policy mpn"  # still handed over when asked for
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


def test_a_mode_asked_for_while_another_builds_does_not_wait_for_it() -> None:
    gate = threading.Event()

    def factory(mode: str) -> str:
        if mode == "ppo":  # an agent: torch and its weights take a while
            gate.wait(10.0)
        return f"policy {mode}"

    loader = PolicyLoader(factory, lambda p: p)
    assert loader.get("ppo") is None
    assert _wait(loader, "gsmpn") == "policy gsmpn"  # the law is ready; ppo is not
    assert loader.pending == ["ppo"]
    assert loader.get("ppo") is None
    gate.set()
    assert _wait(loader, "ppo") == "policy ppo"
    loader.close()


def test_close_drops_the_modes_not_started() -> None:
    gate = threading.Event()
    built: list[str] = []
    lock = threading.Lock()

    def factory(mode: str) -> str:
        gate.wait(10.0)
        with lock:
            built.append(mode)
        return mode

    loader = PolicyLoader(factory, lambda p: p)
    modes = [f"agent{k}" for k in range(MAX_BUILDS + 1)]
    for mode in modes:  # the last waits for a free builder
        loader.get(mode)
    assert loader.pending == modes
    loader.close()
    assert loader.pending == []
    gate.set()
    deadline = time.monotonic() + 10.0
    while len(built) < MAX_BUILDS and time.monotonic() < deadline:
        time.sleep(0.01)
    time.sleep(0.1)  # time for the queued build to start, were it not dropped
    assert sorted(built) == sorted(modes[:MAX_BUILDS])  # finished unused; the queued one never ran
