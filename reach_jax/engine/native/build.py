"""Building and loading the native kernel (`kernel.cc`): compiled on first use with the system's C++ compiler into a
cache folder keyed by a hash of the source, the sizes and the flags, loaded with ctypes and registered with XLA.

Nothing here runs at import. A machine without a compiler, or where the build fails, gets None from `load`, with the
reason in `failure`, and trains on the JAX engine.
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import jax

SOURCE = Path(__file__).with_name("kernel.cc")
BASE_FLAGS = ("-O3", "-std=c++17", "-shared", "-fPIC", "-ffp-contract=off", "-fno-math-errno", "-fno-fast-math")
COMPILE_TIMEOUT = 300  # [s]
ENV_COMPILER = "REACH_NATIVE_CXX"  # a compiler to use instead of $CXX or the first of c++, g++, clang++ on PATH
ENV_CACHE = "REACH_NATIVE_CACHE"  # the cache folder (default ~/.cache/reach_jax/native)


def compiler() -> str | None:
    """The C++ compiler to build with: $REACH_NATIVE_CXX, $CXX, or c++ / g++ / clang++ on PATH; None if there is none.

    REACH_NATIVE_CXX set to an empty string means none (the tests of the fallback use it).
    """
    if ENV_COMPILER in os.environ:
        return shutil.which(os.environ[ENV_COMPILER]) if os.environ[ENV_COMPILER] else None
    for name in (os.environ.get("CXX"), "c++", "g++", "clang++"):
        if name and shutil.which(name):
            return shutil.which(name)
    return None


def cpu_flags() -> tuple[str, ...]:
    """-mavx where the CPU has AVX (no FMA is ever enabled: the kernel must round as XLA:CPU without it does)."""
    try:
        info = Path("/proc/cpuinfo").read_text()
    except OSError:
        return ()
    return ("-mavx",) if " avx " in info or " avx\n" in info else ()


def cache_dir() -> Path:
    """Where built kernels are kept."""
    root = os.environ.get(ENV_CACHE) or os.path.join(os.path.expanduser("~"), ".cache", "reach_jax", "native")
    return Path(root)


class Failure(RuntimeError):
    """The native kernel could not be built or loaded; its message says why in one line."""


@functools.cache
def load(header: str) -> tuple[ctypes.CDLL, str]:
    """(the loaded library, its FFI target's name) of the kernel for the sizes and indices in `header`.

    Raises Failure when there is no compiler or the build fails.

    Args:
      header: the text of consts.h (`layout.header`).
    """
    cxx = compiler()
    if cxx is None:
        raise Failure("no C++ compiler found (set CXX or REACH_NATIVE_CXX)")
    include = jax.ffi.include_dir()
    flags = (*BASE_FLAGS, *cpu_flags())
    key = hashlib.sha256("\0".join((SOURCE.read_text(), header, cxx, *flags, jax.__version__)).encode()).hexdigest()
    folder = cache_dir() / key[:16]
    lib = folder / "kernel.so"
    if not lib.exists():
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=folder) as tmp:
            (Path(tmp) / "consts.h").write_text(header)
            built = Path(tmp) / "kernel.so"
            cmd = [cxx, *flags, f"-I{tmp}", f"-I{include}", str(SOURCE), "-o", str(built), "-lm"]
            try:
                done = subprocess.run(cmd, capture_output=True, text=True, timeout=COMPILE_TIMEOUT, check=False)
            except (OSError, subprocess.TimeoutExpired) as e:
                raise Failure(f"the build failed: {e}") from e
            if done.returncode != 0:
                last = (done.stderr.strip().splitlines() or ["(no output)"])[-1]
                raise Failure(f"the build failed: {last}")
            os.replace(built, lib)  # atomic: concurrent first uses each build and one wins
    handle = ctypes.CDLL(str(lib))
    target = f"reach_native_{key[:16]}"
    jax.ffi.register_ffi_target(target, jax.ffi.pycapsule(handle.ReachNativeChunk), platform="cpu")
    return handle, target
