"""The source-keyed cache: every compiled function of the package is cached under it."""

from __future__ import annotations

import importlib
import pkgutil
import subprocess
import sys
from pathlib import Path

import numba
from numba.core.registry import CPUDispatcher

import follow_env
from follow_env.sim import jit
from follow_env.sim.runner import BatchedSim
from follow_env.tasks.person_follow.config import THESIS
from follow_env.tasks.person_follow.task import TASK


def _all_modules() -> list[str]:
    names = []
    for info in pkgutil.walk_packages(follow_env.__path__, prefix="follow_env."):
        names.append(info.name)
    return names


def _dispatchers() -> list[tuple[str, CPUDispatcher]]:
    found = []
    for name in _all_modules():
        module = importlib.import_module(name)
        for attr, value in vars(module).items():
            if isinstance(value, CPUDispatcher) and value.py_func.__module__ == name:
                found.append((f"{name}.{attr}", value))
    return found


def test_every_compiled_function_is_cached_under_the_source_key() -> None:
    sim = BatchedSim(TASK, THESIS, 1)  # the composed kernels, generated on first use
    found = [
        *_dispatchers(),
        ("composed.step_lanes", sim._step_kernel),
        ("composed.reset_lanes", sim._reset_kernel),
    ]
    assert len(found) > 40  # every compiled model of every layer
    for name, dispatcher in found:
        locator = dispatcher._cache._impl.locator
        assert isinstance(locator, jit.SourceKeyedLocator), name
        assert locator.get_source_stamp() == jit.SOURCE_DIGEST, name
        assert Path(locator.get_cache_path()).is_relative_to(jit.CACHE_ROOT), name


def test_lazily_imported_modules_are_cached_under_the_source_key_too() -> None:
    # The planner is imported only when random_world first plans; its functions inline the
    # counter RNG, so a stale cache would run an old generator.
    trrt = importlib.import_module("follow_env.world.trrt")
    locator = trrt.transition_probability._cache._impl.locator
    assert isinstance(locator, jit.SourceKeyedLocator)


def test_the_digest_covers_every_source_file_of_the_package(tmp_path: Path) -> None:
    package = tmp_path / "pkg"
    (package / "sub").mkdir(parents=True)
    (package / "a.py").write_text("x = 1\n")
    (package / "sub" / "b.py").write_text("y = 2\n")
    before = jit._source_digest(package)
    (package / "sub" / "b.py").write_text("y = 3\n")  # an edit deep in a subpackage
    assert jit._source_digest(package) != before


def test_functions_outside_the_package_keep_numbas_own_cache(tmp_path: Path) -> None:
    script = tmp_path / "user.py"
    script.write_text(
        "import follow_env.sim.jit, numba\n"
        "@numba.njit(cache=True)\n"
        "def f(x):\n    return x + 1\n"
        "f(1)\n"
        "print(type(f._cache._impl.locator).__name__)\n"
    )
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, check=True)
    assert out.stdout.strip() != "SourceKeyedLocator"


def test_njit_defaults_to_a_cached_function() -> None:
    f = jit.njit(lambda x: x)
    assert isinstance(f, numba.core.registry.CPUDispatcher)
    assert f._cache is not None
