"""``follow-train --mkl-intel-paths``: MKL's Intel code paths on any x86-64 CPU.

torch's CPU build carries Intel's MKL, which does the float32 arithmetic of training: the
matrix products (``sgemm``) and the element-wise ``tanh`` of every layer (ATen hands ``tanh``
to MKL's vector math, ``vsTanh``). MKL picks its kernels by asking whether the CPU is an Intel
one (``mkl_serv_intel_cpu_true``); on any other CPU it takes a generic code path whatever the
CPU's instruction set. On a 2-core AMD EPYC with AVX-512 (2026-12-07), ``torch.tanh`` on a
million floats ran MKL's generic kernel (``mkl_vml_kernel_sTanh_EXHAynn``) in 2.6-3.0 ms, where
numpy's took 0.26-0.40 ms and the same call through MKL's Intel path 0.33 ms; with its
``sgemm``, that made training 1.4x slower there (a 400 k-step run of
``ppo_ahead_law_wide.yaml``, one thread: 32.9 s against 22.8 s), and gave other weights than
an Intel CPU with the same instruction set.

With this option the command runs again (``os.execve``, the same arguments) with a one-line
library preloaded (``LD_PRELOAD``) whose ``mkl_serv_intel_cpu_true`` answers yes, so MKL takes
the kernels it would take on an Intel CPU with the same instruction set. MKL still reads the
CPU's features (CPUID), so it asks for no instruction the CPU lacks. On an Intel CPU it changes
nothing. The library is compiled from :data:`SOURCE` by the C compiler (``cc``) once, into
:func:`cache_dir`. The agents act in float64, which gives the same actions under every MKL
code path (``tests/policies/learned/test_networks_any_cpu.py`` checks this setting too), so
only training is affected.

``python -m train.tune`` (the PPO search) takes the same option for its trials' training.
Processes the command starts on this machine (``--workers``, a local Ray) inherit the preload;
the workers of a Ray cluster elsewhere (``--address``) need it in their own environment, and a
run refuses to train where it is missing (:func:`require_active`).
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import platform
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import NoReturn

__all__ = [
    "OPTION",
    "SOURCE",
    "SYMBOL",
    "active",
    "cache_dir",
    "check_platform",
    "mkl_code_path",
    "preload_env",
    "reexec",
    "require_active",
    "shim_library",
]

OPTION = "--mkl-intel-paths"
#: The function MKL's dispatcher asks whether the CPU is an Intel one (exported by torch's
#: ``libtorch_cpu.so``, which links MKL in).
SYMBOL = "mkl_serv_intel_cpu_true"
#: The whole library.
SOURCE = f"int {SYMBOL}(void) {{ return 1; }}\n"


def check_platform() -> None:
    """Raise ``ValueError`` unless this is Linux on x86-64, where torch's CPU build carries MKL
    and ``LD_PRELOAD`` works."""
    machine = platform.machine()
    if sys.platform != "linux" or machine.lower() not in ("x86_64", "amd64"):
        raise ValueError(
            f"{OPTION}: this is {sys.platform} on {machine}; the option applies on Linux on "
            "x86-64 only, where torch's CPU build carries Intel's MKL"
        )


def cache_dir() -> Path:
    """Where the compiled library is kept: ``$XDG_CACHE_HOME/personfollow`` (default
    ``~/.cache/personfollow``)."""
    root = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(root) / "personfollow"


def shim_library() -> Path:
    """The compiled library, compiled now if it is not there yet (to a temporary file renamed
    into place, so a second command never loads a half-written one).

    :raises ValueError: if there is no C compiler, the cache folder cannot be written, or the
        compiler fails (the message says which and gives its output).
    """
    check_platform()
    digest = hashlib.sha256(SOURCE.encode()).hexdigest()[:12]
    folder = cache_dir()
    library = folder / f"libmkl_intel_paths-{digest}.so"
    if library.is_file():
        return library
    compiler = shutil.which(os.environ.get("CC", "cc")) or shutil.which("gcc")
    if compiler is None:
        raise ValueError(
            f"{OPTION}: no C compiler found (cc, gcc, or $CC) to build the one-line library "
            "it preloads; install one (e.g. apt-get install gcc)"
        )
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=folder) as tmp:
            source = Path(tmp) / "mkl_intel_paths.c"
            source.write_text(SOURCE, encoding="utf-8")
            built = Path(tmp) / library.name
            done = subprocess.run(
                [compiler, "-shared", "-fPIC", "-O2", "-o", str(built), str(source)],
                capture_output=True,
                text=True,
                timeout=120,
            )
            if done.returncode != 0:
                output = " ".join((done.stderr or done.stdout).split())
                raise ValueError(
                    f"{OPTION}: {compiler} could not build {library.name} (exit status "
                    f"{done.returncode})" + (f": {output}" if output else "")
                )
            os.replace(built, library)
    except OSError as e:
        raise ValueError(f"{OPTION}: cannot write the library into {folder}: {e}") from None
    return library


def _address(handle: ctypes.CDLL) -> int | None:
    """Where ``handle``'s lookup finds :data:`SYMBOL`, or None if it does not."""
    try:
        return ctypes.cast(getattr(handle, SYMBOL), ctypes.c_void_p).value
    except AttributeError:
        return None


def active(library: Path | None = None) -> bool:
    """Whether this process's global lookup of :data:`SYMBOL`, the one MKL's dispatcher goes
    through, finds ``library``'s (default: :func:`shim_library`'s) rather than MKL's own."""
    library = shim_library() if library is None else library
    found = _address(ctypes.CDLL(None))
    return found is not None and found == _address(ctypes.CDLL(str(library)))


def preload_env(library: Path, env: dict[str, str] | None = None) -> dict[str, str]:
    """``env`` (default: this process's) with ``library`` first in ``LD_PRELOAD``."""
    env = dict(os.environ if env is None else env)
    others = [p for p in env.get("LD_PRELOAD", "").replace(" ", ":").split(":") if p]
    env["LD_PRELOAD"] = ":".join([str(library), *(p for p in others if p != str(library))])
    return env


def reexec(argv: Sequence[str], module: str = "train") -> NoReturn:
    """Run ``python -m <module> argv`` in place of this process, with the library preloaded
    (``module``: ``train`` for ``follow-train``, ``train.tune`` for its PPO search).

    :raises ValueError: as :func:`shim_library`, or if the library, preloaded, is still not
        the one MKL finds (it ran once already: ``LD_PRELOAD`` was set and did not take).
    """
    library = shim_library()
    if os.environ.get("PERSONFOLLOW_MKL_REEXEC") == str(library):
        raise ValueError(
            f"{OPTION}: {library} was preloaded (LD_PRELOAD) and MKL still finds its own "
            f"{SYMBOL}; this Python or torch build does not let it be replaced"
        )
    env = preload_env(library)
    env["PERSONFOLLOW_MKL_REEXEC"] = str(library)  # so that a preload that fails stops here
    sys.stdout.flush()
    sys.stderr.flush()
    os.execve(sys.executable, [sys.executable, "-m", module, *argv], env)


def mkl_code_path() -> int | None:
    """The code path MKL takes on this CPU, as its dispatcher numbers them
    (``mkl_serv_cpu_detect`` in torch's ``libtorch_cpu.so``: 0 is the generic one), or None if
    this torch build carries no MKL. Imports torch."""
    import torch

    library = Path(torch.__file__).parent / "lib" / "libtorch_cpu.so"
    try:
        detect = ctypes.CDLL(str(library)).mkl_serv_cpu_detect
    except (OSError, AttributeError):
        return None
    detect.restype = ctypes.c_int
    return int(detect())


def require_active() -> None:
    """Raise ``ValueError`` unless the library is preloaded in this process and MKL takes a
    code path other than its generic one: a run asked to train on MKL's Intel paths never
    trains on its generic ones (a worker elsewhere, say)."""
    library = shim_library()
    if not active(library):
        raise ValueError(
            f"{OPTION}: this process ({platform.node()}, pid {os.getpid()}) runs without "
            f"{library} preloaded, so MKL would take its generic code paths on a CPU that is "
            f"not Intel's: run follow-train with the option (it preloads the library itself), "
            f"or set LD_PRELOAD={library} in the environment of this process"
        )
    path = mkl_code_path()
    if not path:
        what = "carries no MKL" if path is None else "still has MKL take its generic code path"
        raise ValueError(
            f"{OPTION}: {library} is preloaded, but this torch build {what} "
            f"(mkl_serv_cpu_detect: {path}); train without the option"
        )
