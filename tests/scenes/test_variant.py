"""Mitsuba variant selection."""

from __future__ import annotations

import logging

import pytest

from scenes import mitsuba_variant as mv


@pytest.mark.parametrize(
    ("path", "major"),
    [
        ("/usr/lib/x86_64-linux-gnu/libLLVM-19.so", 19),
        ("/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1", 19),
        ("/usr/lib/llvm-16/lib/libLLVM.so.1", 16),
        ("/usr/lib/x86_64-linux-gnu/libLLVM-14.0.6.so.1", 14),
        ("/opt/libLLVM.so", None),
    ],
)
def test_llvm_version_from_file_name(path, major):
    assert mv.llvm_major_version(path) == major


def test_selects_llvm_when_a_new_enough_libllvm_exists(mitsuba_variant):
    path, _ = mv.find_libllvm()
    if path is None:
        assert mitsuba_variant.backend in ("scalar", "cuda")
        assert "falling back" in mitsuba_variant.reason or mitsuba_variant.backend == "cuda"
    else:
        assert mv.llvm_major_version(path) >= mv.MIN_LLVM_MAJOR
        assert mitsuba_variant.backend in ("llvm", "cuda")
    import mitsuba as mi

    assert mi.variant() == mitsuba_variant.variant


def test_decision_is_logged_once(caplog, monkeypatch):
    monkeypatch.setattr(mv, "_active", None)
    with caplog.at_level(logging.INFO, logger="beacon_sim"):
        mv.select_variant("mono")
        mv.select_variant("mono")
    lines = [r.getMessage() for r in caplog.records if r.getMessage().startswith("Mitsuba variant")]
    assert len(lines) == 1 and "because" not in lines[0] and ":" in lines[0]


def test_bad_override_is_one_line_error(monkeypatch):
    monkeypatch.setattr(mv, "_active", None)
    monkeypatch.setenv(mv.ENV_OVERRIDE, "vulkan")
    with pytest.raises(ValueError, match="BEACON_SIM_VARIANT: expected cuda, llvm, scalar"):
        mv.select_variant("mono")
    monkeypatch.delenv(mv.ENV_OVERRIDE)
    monkeypatch.setattr(mv, "_active", None)
    mv.select_variant("mono")


@pytest.mark.parametrize(
    ("override", "has_cuda", "has_llvm", "expected"),
    [
        ("", True, True, ("cuda", None)),  # a usable GPU wins: renders run there automatically
        ("", True, False, ("cuda", None)),
        ("", False, True, ("llvm", None)),
        ("", False, False, ("scalar", None)),
        ("llvm", True, True, ("llvm", None)),
        ("cuda_ad_mono", True, False, ("cuda", "cuda_ad_mono")),
        ("scalar", True, True, ("scalar", None)),
    ],
)
def test_backend_choice(override, has_cuda, has_llvm, expected):
    from scenes.mitsuba_variant import choose_backend

    variants = ["scalar_rgb", "llvm_ad_mono", "cuda_ad_mono"]
    backend, forced, reason = choose_backend(override, has_cuda, has_llvm, "libLLVM 19 at /x", variants)
    assert (backend, forced) == expected and reason


@pytest.mark.parametrize(("override", "error"), [("cuda", "no usable CUDA device"), ("llvm", "LLVM backend unusable")])
def test_forcing_a_missing_backend_is_one_line_error(override, error):
    from scenes.mitsuba_variant import choose_backend

    with pytest.raises(RuntimeError, match=error):
        choose_backend(override, False, False, "no libLLVM >= 16 found", [])


def test_image_block_reduce_mode_follows_drjit_auto():
    """The render loop's accumulation mode per backend (the CUDA branch checked here on a CPU)."""
    import drjit as dr

    from scenes.render import _block_reduce_mode

    assert _block_reduce_mode(True, 4096, 1 << 20, True) == dr.ReduceMode.Expand
    assert _block_reduce_mode(True, (1 << 20) + 1, 1 << 20, True) == dr.ReduceMode.Local
    assert _block_reduce_mode(False, 4096, 1 << 20, True) == dr.ReduceMode.Local  # CUDA never expands
    assert _block_reduce_mode(False, 4096, 1 << 20, False) == dr.ReduceMode.Direct
