"""The LLVM backend's target is pinned: a render's bytes do not depend on the host's vector width."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

from scenes.llvm_target import PINNED_VECTOR_WIDTH, pin_llvm_target, set_llvm_target
from scenes.render import render_unit_groups
from tests.scenes.test_render_reuse import _spec


def _render_digest() -> str:
    """Digest of the project's render (a lit disc over a floor lit by a ceiling panel, 4 spp, seeded)."""
    images = render_unit_groups(_spec(-0.5, [8, 4, 40, 30]), 4, 5)
    return hashlib.sha256(b"".join(np.ascontiguousarray(images[g]).tobytes() for g in sorted(images))).hexdigest()


def test_a_render_is_the_same_whatever_the_hosts_vector_width(mitsuba_variant):
    """A host whose native width is 4 or 16 lanes (SSE, AVX-512) renders other bytes than one of 8
    (the premise, checked: measured with Mitsuba 3.9.1, Dr.Jit 1.5.0); once pinned, each renders
    the 8-lane bytes."""
    import drjit as dr

    if mitsuba_variant.backend != "llvm":
        pytest.skip("the LLVM backend is not in use")
    target = pin_llvm_target()
    if not target.pinned:
        pytest.skip(target.note)
    assert target.vector_width == PINNED_VECTOR_WIDTH and "+avx512f" not in target.features.split(",")
    threads = dr.thread_count()
    dr.set_thread_count(1)  # the image block's sums in one order (tests/scenes/test_render_reuse.py)
    try:
        pinned = _render_digest()
        for native in (4, 16):
            set_llvm_target(target.cpu, target.features, native)  # a host whose native width this is
            assert _render_digest() != pinned
            assert pin_llvm_target().vector_width == PINNED_VECTOR_WIDTH
            assert _render_digest() == pinned
    finally:
        pin_llvm_target()
        dr.set_thread_count(threads)
