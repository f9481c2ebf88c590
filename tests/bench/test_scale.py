"""bench/scale.py: evaluation throughput per backend, on a tiny grid."""

import pytest

import bench.scale
from follow_env.tasks import task_for_env


@pytest.mark.slow
def test_every_backend_gives_the_same_episodes_and_a_rate_against_this_process(
    monkeypatch: pytest.MonkeyPatch, local_ray
) -> None:
    monkeypatch.setattr(bench.scale, "POLICIES", ("pn",))
    monkeypatch.setattr(bench.scale, "SEEDS", {True: 1})
    monkeypatch.setattr(bench.scale, "EMPTY_UNITS", {True: 8})
    rows = bench.scale.bench_scale(True)  # raises if the backends' episodes differ
    names = [name for name, _, _ in rows]
    n = len(task_for_env("PersonFollow-v0").variants())  # one episode per scenario
    assert names[0] == f"(l) {n} episodes, this process"
    assert names[1:3] == [f"{n} episodes, pool of 2", f"{n} episodes, local Ray"]
    for _, value, _ in rows:
        assert value > 0.0
    assert local_ray.is_initialized()  # the session's Ray is left running
