"""Benchmarks: speed as ratios measured side by side in one run on one machine.

``two_stage_vs_brute_force`` — time to render the same V2 marker (foam + 1 matched
sheet, 5 m, 10° off axis, T6 + 18 mm, 4× oversampled 20 × 20 px crop) to the same
RMS error with the two-stage method (near-field precompute + textured face) and with
brute-force volumetric path tracing. Each method's per-pass noise σ (per-pixel
standard deviation over independent passes, RMS over the marker's pixels, divided by
the marker's mean radiance) and time per pass t are measured; reaching an RMS error ε
takes t·(σ/ε)² (Monte-Carlo error falls as 1/√samples), plus, for the two-stage
method, its near-field precompute, which is also reported apart because it is paid
once per marker configuration and cached.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from scenes.near_field import NearFieldSettings, marker_emission
from scenes.render_cache import RenderCache
from scenes.two_stage_check import MarkerView, brute_force_scene, render_passes, two_stage_scene


def _relative_noise(images: np.ndarray, mask: np.ndarray, reference: np.ndarray) -> float:
    """Normalised RMS noise of one pass: √(mean over the marker of the per-pixel
    variance across passes) / mean radiance of the marker."""
    var = images[:, mask].var(axis=0, ddof=1)
    return float(np.sqrt(var.mean()) / reference[mask].mean())


def two_stage_vs_brute_force(target_rms: float = 0.01, passes: int = 16, brute_spp: int = 256) -> dict:
    """Measure the two-stage speed-up at equal RMS error (see module docstring)."""
    from scenes.beacon import beacon_design
    from scenes.led import led_for_side

    view = MarkerView()
    near = NearFieldSettings()
    with tempfile.TemporaryDirectory() as tmp:
        cache = RenderCache(Path(tmp))
        t0 = time.perf_counter()
        marker_emission(beacon_design("v2"), led_for_side(view.side), view.housing, view.config, view.side, cache, near)
        precompute_s = time.perf_counter() - t0
        two = render_passes(two_stage_scene(view, 16, near, cache), passes)
    brute = render_passes(brute_force_scene(view, brute_spp), passes)
    reference = two.images.mean(axis=0)
    mask = reference > 0.01 * reference.max()
    sigma_two = _relative_noise(two.images, mask, reference)
    sigma_brute = _relative_noise(brute.images, mask, reference)
    t_two = two.seconds_per_pass * (sigma_two / target_rms) ** 2
    t_brute = brute.seconds_per_pass * (sigma_brute / target_rms) ** 2
    return {
        "target_rms": target_rms,
        "two_stage": {
            "spp_per_pass": two.spp_per_pass,
            "seconds_per_pass": two.seconds_per_pass,
            "rms_per_pass": sigma_two,
            "near_field_precompute_s": precompute_s,
            "seconds_to_target": t_two + precompute_s,
            "seconds_to_target_cached": t_two,
        },
        "brute_force": {
            "spp_per_pass": brute.spp_per_pass,
            "seconds_per_pass": brute.seconds_per_pass,
            "rms_per_pass": sigma_brute,
            "seconds_to_target": t_brute,
        },
        "ratio": t_brute / (t_two + precompute_s),
        "ratio_cached": t_brute / t_two,
    }
