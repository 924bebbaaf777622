"""The sensor's temporal noise as fused Dr.Jit kernels (LLVM on the CPU, CUDA on a GPU).

The same EMVA 1288 model as :func:`camera_models.sensor.expose_numpy` (the reference,
used where Dr.Jit has no fast backend), drawn from other random streams:

1. kernel A: λ = max(μ, 0)(1 + PRNU) + μ_dark(1 + DSNU_I), then **exact Poisson by
   inversion** for λ ≤ :data:`INVERSION_MAX_E` (a float64 uniform u per pixel; the count
   is the smallest k with F(k; λ) ≥ u, the CDF summed in float64: almost every pixel of a
   dark frame stops at k = 0 after one comparison). The few pixels with larger λ are
   gathered (``drjit.compress``) and drawn by numpy's exact Poisson sampler.
2. blooming at the full well (numpy, only in the window around pixels that exceed it:
   :func:`camera_models.sensor.bloom_in_place`).
3. kernel B: **one** normal draw per pixel with the summed read-noise variance,
   K·e + N(0, (K σ_pre)² + σ_post,pix²), exact in distribution for the two-stage model
   (a sum of independent normals is normal; blooming acts before both). The normal is
   √2·erfinv(2u − 1) of a float32 uniform u on the grid (i + ½)/2²⁴, which truncates it
   at ±5.42σ: the normal's mass beyond is 6·10⁻⁸, about one pixel of an 18 MP frame, whose
   value then lies at ±5.42σ instead of beyond. Row noise (one draw per row, numpy),
   black level and offset DSNU added, rounded (ties to even) and clipped to the ADC's range.

Streams: each kernel's PCG32 generator is seeded by (seed, stream) through
``numpy.random.SeedSequence`` and runs one sequence per pixel (Dr.Jit offsets the state and
increment of each lane), so a frame's bytes depend only on the seed and the frame, not on
the number of threads. Scalars enter the kernels as opaque values, so one compiled kernel
serves every exposure, gain and seed.
"""

from __future__ import annotations

import importlib
import math
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from camera_models.camera import SensorModel
from camera_models.sensor import _pixel_patterns_of, bloom_in_place

__all__ = ["INVERSION_MAX_E", "available", "expose_drjit", "poisson"]

INVERSION_MAX_E = 32.0
"""Largest mean (e⁻) drawn by inversion in the kernel; above it numpy's exact sampler (PTRS)
draws. Inversion needs about λ + 1 comparisons, so 32 keeps a lane's loop short."""
_MAX_STEPS = 256
"""Safety bound of the inversion loop: F(256; 32) = 1 − 10⁻⁹⁰, far beyond float64's resolution."""
_STREAM_POISSON, _STREAM_READ, _STREAM_ROWS, _STREAM_LARGE = 11, 12, 13, 14


@lru_cache(maxsize=1)
def _backend():
    """The Dr.Jit array module of the fast backend (``drjit.llvm`` or ``drjit.cuda``), or None."""
    from scenes.mitsuba_variant import active_variant

    backend = active_variant().backend
    if backend not in ("llvm", "cuda"):
        return None
    return importlib.import_module(f"drjit.{backend}")


def available() -> bool:
    """Whether a fast Dr.Jit backend is active (else the numpy reference path is used)."""
    return _backend() is not None


def _stream_seeds(seed: int, stream: int) -> tuple[int, int]:
    state, inc = np.random.SeedSequence([seed, stream]).generate_state(2, dtype=np.uint64)
    return int(state), int(inc)


def _mix64(z):
    """splitmix64's finaliser on a Dr.Jit UInt64 array (Steele, Lea & Flood 2014), as in
    :func:`camera_models.sensor._hash_uniform`."""
    z = z + 0x9E3779B97F4A7C15
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9
    z = (z ^ (z >> 27)) * 0x94D049BB133111EB
    return z ^ (z >> 31)


def _rng(m, n: int, seed: int, stream: int):
    """One PCG32 sequence per pixel, its state and increment hashed from (seed, stream, pixel):
    PCG sequences whose increments differ only slightly are correlated: with Dr.Jit's plain
    per-lane offsets, two dark frames of different seeds failed a two-sample χ² test (p = 3·10⁻⁸⁵);
    with the hash they pass (tests/camera_models/test_sensor_equivalence.py)."""
    import drjit as dr

    state, inc = _stream_seeds(seed, stream)
    pixel = dr.arange(m.UInt64, n)
    return m.PCG32(n, _mix64(pixel ^ dr.opaque(m.UInt64, state)), _mix64(pixel ^ dr.opaque(m.UInt64, inc)))


@lru_cache(maxsize=4)  # a whole T6 frame's three patterns are 216 MB
def _patterns_on_device(
    seed: int, prnu: float, dsnu_dark: float, dsnu_offset: float, x0: int, y0: int, height: int, width: int
):
    """The fixed-pattern factors of :func:`camera_models.sensor._pixel_patterns_of`, as Dr.Jit arrays."""
    m = _backend()
    return tuple(
        m.Float(np.ascontiguousarray(a).ravel())
        for a in _pixel_patterns_of(seed, prnu, dsnu_dark, dsnu_offset, x0, y0, height, width)
    )


def _poisson_counts(lam, seed: int):
    """Kernel A on Dr.Jit means λ (float32, evaluated): counts (float32 Dr.Jit array) and the
    pixels left to numpy (their indices and means, numpy arrays)."""
    import drjit as dr

    m = _backend()
    n = dr.width(lam)
    small = lam <= INVERSION_MAX_E
    u = _rng(m, n, seed, _STREAM_POISSON).next_float64()
    lam64 = m.Float64(lam)
    p = dr.exp(-lam64)
    cdf = m.Float64(p)
    k = m.UInt32(0)

    def cond(p, cdf, k):
        return small & (u > cdf) & (k < _MAX_STEPS)

    def body(p, cdf, k):
        k = k + 1
        p = p * lam64 / m.Float64(k)
        return p, cdf + p, k

    p, cdf, k = dr.while_loop((p, cdf, k), cond, body)
    counts = m.Float(k)
    large = dr.compress(~small)
    large_mean = dr.gather(m.Float, lam, large)
    dr.eval(counts, large_mean)
    return counts, large.numpy(), large_mean.numpy()


def _fill_large(counts: NDArray[np.float32], large: NDArray[np.uint32], mean: NDArray[np.float32], seed: int) -> None:
    """Exact Poisson draws (numpy) for the pixels kernel A left, in place."""
    if large.size:
        rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed, _STREAM_LARGE])))
        counts.ravel()[large] = rng.poisson(mean.astype(np.float64))


def poisson(mean: NDArray[np.floating], seed: int) -> NDArray[np.float32]:
    """Poisson counts of the given means (any shape), as the sensor kernel draws them.

    Examples
    --------
    >>> poisson(np.full(4, 0.0), seed=0)
    array([0., 0., 0., 0.], dtype=float32)
    """
    m = _backend()
    if m is None:
        raise RuntimeError("sensor: no fast Dr.Jit backend (LLVM or CUDA) is active")
    mean = np.asarray(mean, dtype=np.float32)
    counts, large, large_mean = _poisson_counts(m.Float(mean.ravel()), seed)
    out = counts.numpy().copy()
    _fill_large(out, large, large_mean, seed)
    return out.reshape(mean.shape)


def _read_out(electrons, offset_fp, row_dn: NDArray[np.float32], width: int, K: float, sd_dn: float, sensor, seed: int):
    """Kernel B: DN = round(K e + N(0, sd²) + row + black + offset), clipped (uint16 numpy array)."""
    import drjit as dr

    m = _backend()
    n = dr.width(electrons)
    u = _rng(m, n, seed, _STREAM_READ).next_float32() + 2.0**-25
    z = dr.erfinv(2.0 * u - 1.0) * math.sqrt(2.0)
    row = dr.gather(m.Float, m.Float(row_dn), dr.arange(m.UInt32, n) // width)
    black = dr.opaque(m.Float, sensor.black_level_DN)
    dn = electrons * dr.opaque(m.Float, K) + z * dr.opaque(m.Float, sd_dn) + row + black + offset_fp
    top = float(min(sensor.white_level_DN, 2**sensor.adc_bits - 1))
    out = m.UInt32(dr.clip(dr.round(dn), 0.0, top))
    dr.eval(out)
    return out.numpy().astype(np.uint16)


def expose_drjit(
    mean_electrons: NDArray[np.floating], sensor: SensorModel, settings, seed: int, x0: int = 0, y0: int = 0
) -> NDArray[np.uint16]:
    """Raw frame (DN, uint16) from each pixel's mean photo-electrons, by the fused kernels.

    Same arguments and model as :func:`camera_models.sensor.expose_numpy`; see the module
    docstring for the algorithm and its one stated approximation.
    """
    import drjit as dr

    settings.validate()
    m = _backend()
    if m is None:
        raise RuntimeError("sensor: no fast Dr.Jit backend (LLVM or CUDA) is active; use the numpy path")
    h, w = mean_electrons.shape
    key = (sensor.fixed_pattern_seed, sensor.prnu_fraction, sensor.dsnu_dark_current_fraction, sensor.dsnu_offset_DN)
    gain_fp, dark_fp, offset_fp = _patterns_on_device(*key, x0, y0, h, w)
    mu = m.Float(np.ascontiguousarray(mean_electrons, dtype=np.float32).ravel())
    dark_e = dr.opaque(m.Float, sensor.dark_current_e_per_s * settings.exposure_s)
    lam = dr.maximum(mu, 0.0) * gain_fp + dark_fp * dark_e
    dr.eval(lam)
    del mu
    electrons, large, large_mean = _poisson_counts(lam, seed)
    del lam
    e = electrons.numpy().reshape(h, w)  # a writable view of the Dr.Jit array
    _fill_large(e, large, large_mean, seed)
    bloom_in_place(e, sensor.full_well_e, sensor.blooming_fraction)
    pre, post = sensor.read_noise_split()
    K = sensor.K_DN_per_e(settings.analog_gain)
    row_sd = post * math.sqrt(sensor.row_noise_fraction)
    pix_sd = post * math.sqrt(1.0 - sensor.row_noise_fraction)
    sd_dn = math.sqrt((K * pre) ** 2 + pix_sd**2)
    rows = np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed, _STREAM_ROWS])))
    row_dn = (rows.standard_normal(h) * row_sd).astype(np.float32)
    # ``e`` is a view of ``electrons``' memory, so the kernel reads the numpy edits above
    return _read_out(electrons, offset_fp, row_dn, w, K, sd_dn, sensor, seed).reshape(h, w)
