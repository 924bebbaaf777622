"""One code-generation target for Dr.Jit's LLVM backend on every x86-64 host with AVX2.

Dr.Jit compiles its kernels for the host CPU, as ``-march=native`` would, and the vector
width it picks changes a render's bytes: the same Mitsuba scene and seed rendered at 4, 8 and
16 lanes gives three different images (measured with Mitsuba 3.9.1 / Dr.Jit 1.5.0, 2026-12-07:
a 32 × 32 path-traced sphere, and whole C270 frames of the project, differ in the last bits
between widths 8 and 16). An AVX2 host runs 8 lanes, an AVX-512 host 16, so the same seed gave
different frames on different machines, and a frame decided at a threshold can flip. Pinning the
width to AVX2's 8 lanes and turning off the AVX-512 instruction sets makes every host with
AVX2 and FMA compile the same kernels (the host's CPU name is kept: it only tunes scheduling).
Hosts without AVX2 and FMA keep their native target; their frames may differ in the last bits.
"""

from __future__ import annotations

import ctypes
import glob
import logging
import os
from dataclasses import dataclass

__all__ = ["PINNED_VECTOR_WIDTH", "LlvmTarget", "pin_llvm_target", "set_llvm_target"]

log = logging.getLogger("beacon_sim")

PINNED_VECTOR_WIDTH = 8
"""Lanes of every LLVM kernel: AVX2's eight 32-bit floats (an AVX-512 host's native width is 16)."""


@dataclass(frozen=True)
class LlvmTarget:
    """Dr.Jit's LLVM code-generation target.

    Attributes
    ----------
    cpu
        LLVM's name of the CPU tuned for (e.g. ``znver3``).
    features
        Comma-separated LLVM feature flags (``+avx2``, ``-avx512f``, …).
    vector_width
        Lanes per kernel instruction.
    pinned
        Whether the portable target (:data:`PINNED_VECTOR_WIDTH`, no AVX-512) is in use.
    note
        Why, in words.
    """

    cpu: str
    features: str
    vector_width: int
    pinned: bool
    note: str


def _core():
    """Dr.Jit's core library (its C API: ``jit_llvm_*``), or None when it cannot be found."""
    import drjit

    paths = glob.glob(os.path.join(os.path.dirname(drjit.__file__), "libdrjit-core.*"))
    return ctypes.CDLL(paths[0]) if paths else None


def _function(lib, mangled: str, restype, argtypes=()):
    """A C++ function of Dr.Jit's core library by its Itanium-mangled name (``jit.h``)."""
    f = getattr(lib, mangled)
    f.restype, f.argtypes = restype, list(argtypes)
    return f


def _current(lib) -> tuple[str, str, int]:
    cpu = _function(lib, "_Z19jit_llvm_target_cpuv", ctypes.c_char_p)()
    features = _function(lib, "_Z24jit_llvm_target_featuresv", ctypes.c_char_p)()
    width = _function(lib, "_Z21jit_llvm_vector_widthv", ctypes.c_uint32)()
    return (cpu or b"").decode(), (features or b"").decode(), int(width)


def set_llvm_target(cpu: str, features: str, vector_width: int) -> None:
    """Set Dr.Jit's LLVM target (``jit_llvm_set_target``); kernels compiled after it use it.

    Parameters
    ----------
    cpu
        LLVM CPU name.
    features
        Comma-separated LLVM feature flags.
    vector_width
        Lanes per instruction, a power of two.
    """
    lib = _core()
    if lib is None:
        raise RuntimeError("Dr.Jit's core library (libdrjit-core) was not found")
    setter = _function(lib, "_Z19jit_llvm_set_targetPKcS0_j", None, (ctypes.c_char_p, ctypes.c_char_p, ctypes.c_uint32))
    setter(cpu.encode(), features.encode(), vector_width)


def pin_llvm_target(vector_width: int = PINNED_VECTOR_WIDTH) -> LlvmTarget:
    """Make Dr.Jit's LLVM backend compile the same kernels on every host with AVX2 and FMA.

    Call after the LLVM backend is initialised (:func:`scenes.mitsuba_variant.select_variant`
    does) and before anything is rendered. Keeps the host's CPU name and features but turns
    off every AVX-512 feature and sets ``vector_width`` lanes. Returns the target in use; on a
    host without AVX2 and FMA, or where Dr.Jit's library cannot be reached, the native one,
    ``pinned`` False.

    Examples
    --------
    >>> from scenes.mitsuba_variant import select_variant
    >>> target = pin_llvm_target() if select_variant().backend == "llvm" else None
    >>> target is None or not target.pinned or target.vector_width == PINNED_VECTOR_WIDTH
    True
    """
    try:
        lib = _core()
        if lib is None:
            raise AttributeError("libdrjit-core")
        cpu, features, width = _current(lib)
    except AttributeError:  # no library, or one without these functions
        return LlvmTarget("", "", 0, False, "Dr.Jit's LLVM target cannot be read here: native code")
    flags = [f for f in features.split(",") if f]
    if "+avx2" not in flags or "+fma" not in flags:
        note = (
            f"no AVX2 and FMA on this {cpu or 'CPU'}: native code, {width} lanes (frames may differ in the last bits)"
        )
        return LlvmTarget(cpu, features, width, False, note)
    portable = ",".join("-" + f[1:] if f.startswith("+avx512") else f for f in flags)
    try:
        set_llvm_target(cpu, portable, vector_width)
    except AttributeError:
        return LlvmTarget(cpu, features, width, False, "Dr.Jit's LLVM target cannot be set here: native code")
    cpu, features, width = _current(lib)
    note = f"{cpu}, AVX2 without AVX-512, {width} lanes: the same kernels on every AVX2 host"
    return LlvmTarget(cpu, features, width, width == vector_width, note)
