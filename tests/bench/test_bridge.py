"""bench/bridge.py: the decoder benchmark runs and recovers every frame it sent."""

from __future__ import annotations

from bench.bridge import bench_bridge


def test_quick_benchmark_recovers_every_frame_of_both_framings() -> None:
    rows = {name: (value, ratio) for name, value, ratio in bench_bridge(quick=True)}
    for framing in ("reference", "robust"):
        found, text = rows[f"{framing}: frames recovered"]
        assert text.startswith(f"{found:.0f}/{found:.0f},")  # recovered == sent
        assert found == 1000
        assert rows[f"{framing}: decoder (MB/s)"][0] > 0
    assert rows["robust: frames recovered"][1].endswith(", 0 false")
