"""``follow-train --mkl-intel-paths``: MKL's Intel code paths on any x86-64 CPU.

torch's CPU build carries Intel's MKL, which does the float32 arithmetic of training: the
matrix products (``sgemm``) and the element-wise ``tanh`` of every layer (ATen hands ``tanh``
to MKL's vector math, ``vsTanh``). MKL picks its kernels by asking whether the CPU is an Intel
one (``mkl_serv_intel_cpu_true``); on any other CPU it takes a generic code path whatever the
CPU's instruction set. On a 2-core AMD EPYC with AVX-512 (2026-12-07), ``torch.tanh`` on a
million floats ran MKL's generic kernel (``mkl_vml_kernel_sTanh_EXHAynn``) in 2.6-3.0 ms, where
numpy's took 0.26-0.40 ms and the same call through MKL's Intel path 0.33 ms; with its
``sgemm``, that made training 1.3-1.4x slower there (400 k steps of
``ppo_ahead_law_wide.yaml``'s learning, one thread: 29.5-32.9 s in three runs, against 22.8 s
in one with the library below), and gave other weights than the Intel Xeon (AVX-512) the
shipped agents were trained on; with it, the same weights.

With this option the command runs again (``os.execve`` of the same command line) with a
one-line library preloaded (``LD_PRELOAD``) whose ``mkl_serv_intel_cpu_true`` answers yes, so
MKL takes the kernels it gives an Intel CPU with the same instruction set. (MKL still reads the
CPU's features, CPUID, to choose among them.) On an Intel CPU, where MKL's own check answers
yes, it should change nothing (not measured on one; the tests check that MKL reports the same
code path there). The library is compiled from :data:`SOURCE` by the C compiler (``cc``) once,
into :func:`cache_dir`. The agents act in float64, which gives the same actions under every MKL
code path (``tests/policies/learned/test_networks_any_cpu.py`` checks this setting too), so
only training is affected. ``python -m train.tune`` (the PPO search) takes the same option for
its trials' training.

Processes the command starts on this machine (``--workers``, a local Ray) inherit the preload;
the workers of a Ray cluster elsewhere (``--address``) need it in their own environment, and a
run refuses to train where it is missing or MKL still reports its generic code path
(:func:`require_active`).
"""

from __future__ import annotations

import contextlib
import ctypes
import hashlib
import os
import platform
import shutil
import stat
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
    "c_compiler",
    "cache_dir",
    "check_platform",
    "cpu_vendor",
    "ensure_preloaded",
    "library_path",
    "mkl_code_path",
    "plain_env",
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
#: Set in the command run again, so that a preload that did not take stops there.
_REEXEC = "PERSONFOLLOW_MKL_REEXEC"


def check_platform() -> None:
    """Raise ``ValueError`` unless this is Linux on x86-64, where torch's CPU build carries MKL
    and ``LD_PRELOAD`` works."""
    machine = platform.machine()
    if sys.platform != "linux" or machine.lower() not in ("x86_64", "amd64"):
        raise ValueError(
            f"{OPTION}: this is {sys.platform} on {machine}; the option applies on Linux on "
            "x86-64 only, where torch's CPU build carries Intel's MKL"
        )


def cpu_vendor() -> str:
    """The CPU's vendor as ``/proc/cpuinfo`` gives it (``GenuineIntel``, ``AuthenticAMD``), or
    "" where there is none: what MKL's check asks."""
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text(encoding="utf-8").splitlines():
            if line.startswith("vendor_id"):
                return line.split(":", 1)[1].strip()
    return ""


def c_compiler() -> str | None:
    """The C compiler the library is built with: ``$CC`` (default ``cc``), else ``gcc``; None
    if there is neither."""
    return shutil.which(os.environ.get("CC", "cc")) or shutil.which("gcc")


def cache_dir() -> Path:
    """Where the compiled library is kept: ``$XDG_CACHE_HOME/personfollow`` (default
    ``~/.cache/personfollow``)."""
    root = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(root) / "personfollow"


def library_path() -> Path:
    """Where :func:`shim_library` keeps the library (named by its source's digest), built or
    not."""
    digest = hashlib.sha256(SOURCE.encode()).hexdigest()[:12]
    return cache_dir() / f"libmkl_intel_paths-{digest}.so"


def _answers_yes(library: Path) -> bool:
    """Whether ``library`` is a shared object that loads and whose :data:`SYMBOL` returns 1 (a
    damaged file is not; its header is read first, as a process that loaded the file before
    it was replaced gets the old one from ``dlopen``)."""
    try:
        with library.open("rb") as f:
            if f.read(4) != b"\x7fELF":
                return False
        return getattr(ctypes.CDLL(str(library)), SYMBOL)() == 1
    except (OSError, AttributeError):
        return False


def _lstat(path: Path) -> os.stat_result | None:
    """``os.lstat(path)``, or None where nothing is there.

    :raises ValueError: where the path cannot be read (naming it).
    """
    try:
        return os.lstat(path)
    except (FileNotFoundError, NotADirectoryError):
        return None
    except OSError as e:
        raise ValueError(
            f"{OPTION}: cannot read {path} ({e.strerror}); set XDG_CACHE_HOME to a folder of your "
            "own"
        ) from None


def _refuse_owner(path: Path, uid: int) -> ValueError:
    return ValueError(
        f"{OPTION}: {path} belongs to user id {uid}, neither this user ({os.geteuid()}) nor "
        "root, who could replace the library it preloads; set XDG_CACHE_HOME to a folder of "
        "your own"
    )


def _refuse_roots(path: Path, mode: int) -> ValueError:
    return ValueError(
        f"{OPTION}: {path} belongs to root and can be written by other users (mode "
        f"{stat.S_IMODE(mode):#o}); set XDG_CACHE_HOME to a folder of your own"
    )


def _check_above(folder: Path) -> None:
    """The folders above ``folder``, as written and as resolved, and the symbolic links on the
    way: each this user's or root's, and a folder writable by other users only with the sticky
    bit (as ``/tmp``), so that no one else can rename the cache folder away and put another in
    its place (ssh checks the path to its keys so).

    :raises ValueError: naming the first path that fails, its owner or mode.
    """
    me = os.geteuid()
    seen: set[Path] = set()
    for path in [*folder.parents, *folder.resolve().parents]:
        if path in seen:
            continue
        seen.add(path)
        st = _lstat(path)
        if st is None:
            continue
        if st.st_uid not in (me, 0):
            raise _refuse_owner(path, st.st_uid)
        if stat.S_ISDIR(st.st_mode) and st.st_mode & 0o022 and not st.st_mode & stat.S_ISVTX:
            raise ValueError(
                f"{OPTION}: {path} can be written by other users (mode "
                f"{stat.S_IMODE(st.st_mode):#o}, no sticky bit), who could replace the library "
                "in a folder below it; set XDG_CACHE_HOME to a folder only you can write"
            )


def _check_folder(folder: Path) -> None:
    """The cache folder, if it is there: a folder (or a link to one that this user or root
    owns), this user's or root's, and writable by no one else. This user's folder writable by
    the group or others (one an earlier version made under umask 002, or the compiled kernels'
    cache beside it) loses those rights here.

    :raises ValueError: naming the folder and what is wrong.
    """
    link = _lstat(folder)
    if link is None:
        return
    me = os.geteuid()
    if stat.S_ISLNK(link.st_mode) and link.st_uid not in (me, 0):
        raise _refuse_owner(folder, link.st_uid)
    st = _lstat(folder.resolve())
    if st is None or not stat.S_ISDIR(st.st_mode):
        raise ValueError(f"{OPTION}: {folder} is not a folder; remove it")
    if st.st_uid not in (me, 0):
        raise _refuse_owner(folder, st.st_uid)
    if st.st_mode & 0o022:
        if st.st_uid != me:
            raise _refuse_roots(folder, st.st_mode)
        try:
            os.chmod(folder.resolve(), stat.S_IMODE(st.st_mode) & ~0o022)
        except OSError as e:
            raise ValueError(
                f"{OPTION}: {folder} can be written by other users (mode "
                f"{stat.S_IMODE(st.st_mode):#o}) and cannot be made yours alone ({e.strerror}); "
                "set XDG_CACHE_HOME to a folder of your own"
            ) from None


def _library_usable(library: Path) -> bool:
    """Whether the library is there to be loaded: this user's or root's and writable by no one
    else. One of this user's that others could write (an earlier version built it under umask
    002) is removed, unloaded, to be built again.

    :raises ValueError: for a library another user owns, or root's writable by others.
    """
    st = _lstat(library)
    if st is None:
        return False
    me = os.geteuid()
    if st.st_uid not in (me, 0):
        raise _refuse_owner(library, st.st_uid)
    if not stat.S_ISREG(st.st_mode):
        raise ValueError(f"{OPTION}: {library} is not a file; remove it")
    if st.st_mode & 0o022:
        if st.st_uid != me:
            raise _refuse_roots(library, st.st_mode)
        try:
            library.unlink()
        except OSError as e:
            raise ValueError(
                f"{OPTION}: {library} can be written by other users (mode "
                f"{stat.S_IMODE(st.st_mode):#o}) and cannot be removed ({e.strerror}); remove it"
            ) from None
        return False
    return True


def shim_library() -> Path:
    """The compiled library, compiled now if it is not there yet or does not load (to a
    temporary file renamed into place, so a second command never loads a half-written one).
    Whatever is in the file runs in every process the option starts, so a library another user
    could have put there or changed is never loaded, not even to check it: the folders above
    (:func:`_check_above`), the folder (:func:`_check_folder`, again once it is made) and the
    file (:func:`_library_usable`, again once it is built) must be this user's or root's, and
    writable by no one else; a folder it makes is this user's alone (mode 0700).

    :raises ValueError: if this is not Linux on x86-64, the cache folder's path cannot stand in
        ``LD_PRELOAD`` or cannot be written, a folder on its path or the library is another
        user's or writable by others, there is no C compiler, or the compiler fails (the message
        says which and gives its output).
    """
    check_platform()
    library = library_path()
    folder = library.parent
    if any(c in str(library) for c in " :"):  # ld.so splits LD_PRELOAD on both
        raise ValueError(
            f"{OPTION}: the library's folder {folder} has a space or a colon in its path, "
            "which LD_PRELOAD cannot hold; set XDG_CACHE_HOME to a folder without them"
        )
    _check_above(folder)
    _check_folder(folder)
    if _library_usable(library) and _answers_yes(library):
        return library
    compiler = c_compiler()
    if compiler is None:
        raise ValueError(
            f"{OPTION}: no C compiler found (cc, gcc, or $CC) to build the one-line library "
            "it preloads; install one (e.g. apt-get install gcc)"
        )
    try:
        folder.mkdir(mode=0o700, parents=True, exist_ok=True)
        _check_folder(folder)  # whoever made it: another user may have, since the check above
        with tempfile.TemporaryDirectory(dir=folder) as tmp:
            source = Path(tmp) / "mkl_intel_paths.c"
            source.write_text(SOURCE, encoding="utf-8")
            built = Path(tmp) / library.name
            try:
                done = subprocess.run(
                    [compiler, "-shared", "-fPIC", "-O2", "-o", str(built), str(source)],
                    capture_output=True,
                    text=True,
                    timeout=120,
                )
            except subprocess.TimeoutExpired:
                raise ValueError(f"{OPTION}: {compiler} took over 120 s; nothing built") from None
            if done.returncode != 0:
                output = " ".join((done.stderr or done.stdout).split())
                raise ValueError(
                    f"{OPTION}: {compiler} could not build {library.name} (exit status "
                    f"{done.returncode})" + (f": {output}" if output else "")
                )
            built.chmod(0o755)  # the compiler's output follows the umask, which may be 002
            os.replace(built, library)
    except OSError as e:
        raise ValueError(f"{OPTION}: cannot write the library into {folder}: {e}") from None
    if not _library_usable(library):  # as any library the cache gives: checked where it lies
        raise ValueError(f"{OPTION}: {library} changed while it was built; run the command again")
    return library


def active() -> bool:
    """Whether this process's global lookup of :data:`SYMBOL` finds a definition that answers
    yes. MKL's own one is not in the global scope (torch loads ``libtorch_cpu.so`` locally), so
    this is a preloaded library's, whatever its path."""
    try:
        found = getattr(ctypes.CDLL(None), SYMBOL)
    except AttributeError:
        return False
    found.restype = ctypes.c_int
    return found() == 1


def mkl_code_path() -> int | None:
    """The code path MKL takes on this CPU, as its dispatcher numbers them
    (``mkl_serv_cpu_detect``: 0 is the generic one), or None if this torch build carries no
    MKL where it is looked for (in ``libtorch_cpu.so``, or a library loaded globally). Imports
    torch."""
    import torch

    handles = []
    with_mkl = Path(torch.__file__).parent / "lib" / "libtorch_cpu.so"
    with contextlib.suppress(OSError, TypeError, AttributeError):  # loaded already, or none
        handles.append(ctypes.CDLL(str(with_mkl), mode=os.RTLD_NOLOAD))
    with contextlib.suppress(OSError, TypeError):  # no global handle off Linux
        handles.append(ctypes.CDLL(None))
    for handle in handles:
        try:
            detect = handle.mkl_serv_cpu_detect
        except AttributeError:
            continue
        detect.restype = ctypes.c_int
        return int(detect())
    return None


def plain_env(env: dict[str, str] | None = None) -> dict[str, str]:
    """``env`` (default: this process's) without a preload, the option's or any, nor the mark
    of a command run again: what a command that must choose for itself starts from."""
    env = os.environ if env is None else env
    return {k: v for k, v in env.items() if k not in ("LD_PRELOAD", _REEXEC)}


def preload_env(library: Path, env: dict[str, str] | None = None) -> dict[str, str]:
    """``env`` (default: this process's) with ``library`` first in ``LD_PRELOAD``."""
    env = dict(os.environ if env is None else env)
    others = [p for p in env.get("LD_PRELOAD", "").replace(" ", ":").split(":") if p]
    env["LD_PRELOAD"] = ":".join([str(library), *(p for p in others if p != str(library))])
    return env


def ensure_preloaded(argv: Sequence[str]) -> None:
    """Return if MKL's Intel code paths are preloaded in this process (:func:`active`), else
    run the command again with them (:func:`reexec`, which does not return).

    :raises ValueError: as :func:`reexec`.
    """
    if not active():
        reexec(argv)


def reexec(argv: Sequence[str]) -> NoReturn:
    """Run this process's command line again in its place (``sys.orig_argv``: the same
    program, interpreter options and arguments), with the library preloaded.

    :param argv: the arguments the caller parsed, which must be this process's: a caller that
        passed others (a ``main(argv)`` called from Python) is refused, since it would be
        replaced by a command it did not run.
    :raises ValueError: as :func:`shim_library`, for such a caller, or if the library,
        preloaded, is still not what this process finds (it ran once already).
    """
    if list(argv) != sys.argv[1:] or sys.argv[0] == "-":  # a script read from stdin: gone
        raise ValueError(
            f"{OPTION}: runs the command again preloaded, so it needs this process's own "
            "command line; from Python, start the process with LD_PRELOAD set to "
            "train.mkl_paths.shim_library() instead"
        )
    library = shim_library()
    if os.environ.get(_REEXEC) == str(library):
        raise ValueError(
            f"{OPTION}: the command ran again with LD_PRELOAD={library} and this process still "
            f"does not find its {SYMBOL} (a message from ld.so above, if any, says why)"
        )
    env = preload_env(library)
    env[_REEXEC] = str(library)
    sys.stdout.flush()
    sys.stderr.flush()
    os.execve(sys.executable, [sys.executable, *sys.orig_argv[1:]], env)


def require_active() -> None:
    """Raise ``ValueError`` unless a library answering yes for :data:`SYMBOL` is preloaded in
    this process and MKL takes a code path other than its generic one: a run asked to train on
    MKL's Intel paths never trains on its generic ones (a worker elsewhere, say). Builds
    nothing."""
    where = f"this process ({platform.node()}, pid {os.getpid()})"
    if not active():
        raise ValueError(
            f"{OPTION}: {where} runs without the library preloaded, so MKL would take its "
            "generic code paths on a CPU that is not Intel's: run follow-train with the option "
            "(it preloads the library itself), or set LD_PRELOAD to the library in this "
            f"process's environment (follow-train builds it at {library_path()} on this machine)"
        )
    path = mkl_code_path()
    if not path:
        what = "carries no MKL" if path is None else "still has MKL take its generic code path"
        raise ValueError(
            f"{OPTION}: the library is preloaded in {where}, but this torch build {what} "
            f"(mkl_serv_cpu_detect: {path}); train without the option"
        )
