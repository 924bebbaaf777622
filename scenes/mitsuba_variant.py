"""Choose and activate the Mitsuba 3 variant: CUDA, then LLVM, then scalar.

Mitsuba's fast CPU backend JIT-compiles through libLLVM, which must be version 16 or
newer: Debian's libLLVM 14 fails to load and 15 aborts on ``fmaximum``. Dr.Jit finds
the library through ``DRJIT_LIBLLVM_PATH``, which must be set before ``drjit`` is
imported, so this module sets it itself after searching the usual install locations.

Colour mode
-----------
The beacon-scale renders use the *mono* variants: every surface at beacon scale is
spectrally grey, so light transport factorises into a scalar image per light source
times that source's known spectrum (see :mod:`scenes.radiance`). This is exact for
grey surfaces, has no wavelength-sampling noise and costs one channel instead of one
per band. Spectral variants are selected with ``mode="spectral"`` where a material is
not grey (dyed paper, in the near-field marker stage).

The LLVM backend compiles for one portable target on every AVX2 host
(:mod:`scenes.llvm_target`), so a seed gives the same frame on every such machine.

Override with ``BEACON_SIM_VARIANT``: a backend (``cuda``, ``llvm``, ``scalar``) or a
full Mitsuba variant name (``llvm_ad_mono``).
"""

from __future__ import annotations

import glob
import logging
import os
import re
from dataclasses import dataclass
from pathlib import Path

from scenes.llvm_target import pin_llvm_target

__all__ = [
    "ENV_OVERRIDE",
    "ENV_THREADS",
    "MIN_LLVM_MAJOR",
    "VariantChoice",
    "active_variant",
    "choose_backend",
    "find_libllvm",
    "llvm_major_version",
    "select_variant",
]

log = logging.getLogger("beacon_sim")

MIN_LLVM_MAJOR = 16
ENV_OVERRIDE = "BEACON_SIM_VARIANT"
ENV_THREADS = "BEACON_SIM_THREADS"
"""Threads of the LLVM backend in this process (set by the sweep runner for its workers)."""

_LLVM_GLOBS = (
    "/usr/lib/x86_64-linux-gnu/libLLVM*.so*",
    "/usr/lib/aarch64-linux-gnu/libLLVM*.so*",
    "/usr/lib/llvm-*/lib/libLLVM*.so*",
    "/usr/lib64/libLLVM*.so*",
    "/opt/homebrew/opt/llvm/lib/libLLVM.dylib",
    "/usr/local/opt/llvm/lib/libLLVM.dylib",
)

# Mitsuba ships no scalar mono variant; scalar_rgb with grey inputs is equivalent.
_VARIANTS = {
    ("cuda", "mono"): "cuda_ad_mono",
    ("llvm", "mono"): "llvm_ad_mono",
    ("scalar", "mono"): "scalar_rgb",
    ("cuda", "spectral"): "cuda_ad_spectral",
    ("llvm", "spectral"): "llvm_ad_spectral",
    ("scalar", "spectral"): "scalar_spectral",
}


@dataclass(frozen=True)
class VariantChoice:
    """The active Mitsuba variant and why it was chosen."""

    backend: str  # "cuda", "llvm" or "scalar"
    variant: str  # Mitsuba variant name
    reason: str


def llvm_major_version(path: str | os.PathLike[str]) -> int | None:
    """Major version of a libLLVM shared library, read from its file name.

    Handles ``libLLVM-19.so``, ``libLLVM.so.19.1`` and ``/usr/lib/llvm-19/lib/libLLVM.so.1``.
    Returns ``None`` when no version can be read.
    """
    p = Path(path)
    m = re.search(r"libLLVM-(\d+)", p.name) or re.search(r"libLLVM\.so\.(\d+)\.", p.name)
    if m is None:
        m = re.search(r"llvm-(\d+)", str(p.parent))
    return int(m.group(1)) if m else None


def find_libllvm(min_major: int = MIN_LLVM_MAJOR) -> tuple[str | None, str]:
    """Find the newest libLLVM with major version >= ``min_major``.

    Returns
    -------
    path, message
        ``path`` is ``None`` when no suitable library exists; ``message`` says what was
        found either way. A ``DRJIT_LIBLLVM_PATH`` already set by the user wins when it
        points at an existing file of a usable version.
    """
    preset = os.environ.get("DRJIT_LIBLLVM_PATH")
    if preset and Path(preset).is_file():
        major = llvm_major_version(preset)
        if major is None or major >= min_major:
            return preset, f"DRJIT_LIBLLVM_PATH={preset} (set by the user)"
    found: list[tuple[int, str]] = []
    for pattern in _LLVM_GLOBS:
        for f in glob.glob(pattern):
            major = llvm_major_version(f)
            if major is not None and Path(f).is_file():
                found.append((major, f))
    usable = sorted(x for x in found if x[0] >= min_major)
    if usable:
        major, path = usable[-1]
        return path, f"libLLVM {major} at {path}"
    versions = sorted({m for m, _ in found})
    return None, (
        f"no libLLVM >= {min_major} found (found versions: {versions or 'none'}); "
        "install libllvm19 (scripts/setup.sh does)"
    )


_active: VariantChoice | None = None


def select_variant(mode: str = "mono") -> VariantChoice:
    """Pick and activate the best Mitsuba variant for ``mode`` ("mono" or "spectral").

    The first call decides the backend (CUDA > LLVM > scalar, or the override) and logs
    one line saying which and why; later calls reuse that backend, switching only the
    colour mode. Must run before anything else imports ``drjit``, which is why the
    project imports Mitsuba only through this function.
    """
    global _active
    if mode not in ("mono", "spectral"):
        raise ValueError(f"mode: expected 'mono' or 'spectral', got {mode!r}")
    if _active is None:
        backend, forced_variant, reason = _decide_backend()
        variant = forced_variant or _VARIANTS[(backend, mode)]
        _active = VariantChoice(backend, variant, reason)
        log.info("Mitsuba variant %s: %s", variant, reason)
        if backend == "llvm":
            log.info("Dr.Jit LLVM target: %s", pin_llvm_target().note)  # the same bytes on every AVX2 host
        threads = os.environ.get(ENV_THREADS, "").strip()
        if threads and backend == "llvm":
            import drjit as dr

            # a sweep's worker processes share the cores instead of each taking all of them
            dr.set_thread_count(max(1, int(threads)))
    else:
        variant = _VARIANTS[(_active.backend, mode)]
    import mitsuba as mi

    if mi.variant() != variant:
        mi.set_variant(variant)
        from scenes.plugins import register_plugins

        register_plugins()
    return VariantChoice(_active.backend, variant, _active.reason)


def _decide_backend() -> tuple[str, str | None, str]:
    """Return (backend, forced variant or None, reason)."""
    override = os.environ.get(ENV_OVERRIDE, "").strip()
    llvm_path, llvm_msg = find_libllvm()
    if llvm_path:
        os.environ["DRJIT_LIBLLVM_PATH"] = llvm_path
    import drjit as dr
    import mitsuba as mi

    has_cuda = dr.has_backend(dr.JitBackend.CUDA)
    has_llvm = llvm_path is not None and dr.has_backend(dr.JitBackend.LLVM)
    choice = choose_backend(override, has_cuda, has_llvm, llvm_msg, mi.variants())
    if choice[0] == "scalar" and not override:
        log.warning("Mitsuba: %s", choice[2])
    return choice


def choose_backend(
    override: str, has_cuda: bool, has_llvm: bool, llvm_msg: str, variants: list[str]
) -> tuple[str, str | None, str]:
    """The backend to use, a variant forced by name (or None) and why: the override when
    it names a usable backend or variant, else CUDA when a GPU is usable, else LLVM, else
    scalar. Pure, so every branch (the GPU's included) is tested on any machine.

    Parameters
    ----------
    override
        ``BEACON_SIM_VARIANT`` (empty: none): a backend or a full variant name.
    has_cuda, has_llvm
        Whether Dr.Jit can use each backend here.
    llvm_msg
        Where libLLVM was found, or why it was not.
    variants
        Mitsuba's compiled variants.
    """
    if override:
        backend = override.split("_")[0]
        if backend not in ("cuda", "llvm", "scalar"):
            raise ValueError(f"{ENV_OVERRIDE}: expected cuda, llvm, scalar or a variant name, got {override!r}")
        if backend == "llvm" and not has_llvm:
            raise RuntimeError(f"{ENV_OVERRIDE}={override}: LLVM backend unusable: {llvm_msg}")
        if backend == "cuda" and not has_cuda:
            raise RuntimeError(f"{ENV_OVERRIDE}={override}: no usable CUDA device")
        forced = override if override in variants else None
        return backend, forced, f"forced by {ENV_OVERRIDE}={override}"
    if has_cuda:
        return "cuda", None, "a CUDA GPU is usable"
    if has_llvm:
        return "llvm", None, f"no CUDA GPU; LLVM backend through {llvm_msg}"
    return "scalar", None, f"no CUDA GPU and {llvm_msg}: falling back to the slow scalar variant"


def active_variant() -> VariantChoice:
    """The variant chosen so far, selecting the default (mono) one if none was."""
    return _active if _active is not None else select_variant()
