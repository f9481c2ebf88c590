"""A learned agent acts the same on every CPU (policies.learned.networks: it acts in float64).

Other CPUs are stood in for by running the agent in a subprocess under other instruction sets:
MKL_ENABLE_INSTRUCTIONS caps the kernels of MKL (torch's matrix products, and its tanh, which
ATen hands to MKL's vector math), ATEN_CPU_CAPABILITY those of torch's own element-wise ones, as
a CPU without AVX-512, or without AVX2, would have them picked. MKL heeds
MKL_ENABLE_INSTRUCTIONS on Intel CPUs only; on an AMD EPYC its float32 kernels do not move under
it (seen on 2026-12-07), so a third setting asks for the COMPATIBLE branch of MKL's Conditional
Numerical Reproducibility (MKL_CBWR=COMPATIBLE: its SSE2 code path for any x86-64 CPU), which
moves them there. A fourth preloads ``follow-train --mkl-intel-paths``'s library
(:mod:`train.mkl_paths`), which gives a CPU that is not Intel's the kernels of an Intel one: an
agent acts the same with it as without.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from train.mkl_paths import cpu_vendor, plain_env, preload_env, shim_library

# Each stands for a CPU of another kind: one with AVX2 and no AVX-512, one older still, and
# MKL's kernels for any x86-64 CPU (the one setting that moves MKL's kernels on an AMD CPU).
SETTINGS = {
    "avx2": {"MKL_ENABLE_INSTRUCTIONS": "AVX2", "ATEN_CPU_CAPABILITY": "avx2"},
    "sse4_2": {"MKL_ENABLE_INSTRUCTIONS": "SSE4_2", "ATEN_CPU_CAPABILITY": "default"},
    "compatible": {"MKL_CBWR": "COMPATIBLE", "ATEN_CPU_CAPABILITY": "default"},
}
ROWS = 4000

# Acts on ROWS observations drawn within the agent's view (seeded) and saves the actions: in
# float64, as the agent acts, and, as the control, with the same network in float32.
_ACT = """
import sys
import numpy as np
import torch
from follow_env.sim.checks import load_yaml
from policies import make_policy
from policies.learned import networks

agent = make_policy(sys.argv[1])._agent
box = agent.model.observation_space
rows = np.random.default_rng(11).uniform(
    np.maximum(box.low, -3), np.minimum(box.high, 3), (int(sys.argv[3]), *box.shape)
).astype(np.float32)
wide = agent.model.act(rows)
# The control: the same network loaded again and left in float32.
networks.widened = lambda policy, copy=True: policy
config = load_yaml(agent.files.config.read_text(encoding="utf-8"))
kind = config["hyperparams"].get("policy")
narrow_net = networks.load_network(agent.files.model, agent.algo, kind, RuntimeError)
with torch.inference_mode():
    narrow = np.concatenate(
        [narrow_net._gaussian(torch.from_numpy(r[None])).numpy() for r in rows]
    )
narrow = np.clip(narrow, narrow_net._low, narrow_net._high)  # as Network.act clips its own
np.savez(sys.argv[2], wide=wide, narrow=narrow)
"""


def _intel_paths() -> dict[str, dict[str, str]]:
    """The fourth setting, where ``--mkl-intel-paths``'s library can be had: Linux on x86-64
    with a C compiler (the Makefile's machines); elsewhere the other three run alone."""
    try:
        return {"intel_paths": preload_env(shim_library(), {})}
    except ValueError:
        return {}


def _actions(agent: str, out: Path, settings: dict[str, str]) -> dict[str, np.ndarray]:
    # The machine's own kernels for "here": none of the settings' variables inherited (nor
    # a preload, which may be --mkl-intel-paths's library).
    inherited = {k: v for k, v in plain_env().items() if not k.startswith(("MKL_", "ATEN_"))}
    env = {**inherited, **settings}
    root = Path(__file__).resolve().parents[3]
    subprocess.run(
        [sys.executable, "-c", _ACT, agent, str(out), str(ROWS)],
        env=env,
        cwd=root,
        check=True,
        timeout=300,
    )
    with np.load(out) as saved:
        return {key: saved[key] for key in saved.files}


@pytest.mark.slow
@pytest.mark.parametrize("agent", ["ppo", "ppo_mecanum"])
def test_an_agent_acts_bit_for_bit_the_same_under_other_instruction_sets(
    agent: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))  # the library, not the user's
    here = _actions(agent, tmp_path / "here.npz", {})
    moved: dict[str, float] = {}
    for name, settings in {**SETTINGS, **_intel_paths()}.items():
        there = _actions(agent, tmp_path / f"{name}.npz", settings)
        np.testing.assert_array_equal(there["wide"], here["wide"], err_msg=name)
        moved[name] = float((there["narrow"] != here["narrow"]).mean())
    # The control: in float32 the same network does act differently under at least one of
    # them, so the settings do stand for other CPUs' kernels on this machine.
    assert max(moved.values()) > 0.0, f"no setting moved the float32 actions: {moved}"
    # The library moves MKL's float32 kernels on a CPU that is not Intel's (2,705 of ppo's
    # 8,000 entries on an AMD EPYC), and none on an Intel one, whose kernels they are already.
    if "intel_paths" in moved:
        if cpu_vendor() == "GenuineIntel":
            assert moved["intel_paths"] == 0.0
        else:
            assert moved["intel_paths"] > 0.0
    # And float64's actions are float32's but for its rounding.
    np.testing.assert_allclose(here["wide"], here["narrow"], rtol=1e-5, atol=1e-6)
