"""The image sensor as the EMVA 1288 linear model, with a Bayer colour filter array.

For each pixel (channel c set by the CFA, full-frame parity):

1. mean photo-electrons μ_e (from :mod:`camera_models.optics`) × (1 + PRNU)          [fixed pattern]
2. + dark electrons μ_d = I_dark (1 + DSNU_I) t                                     [fixed pattern]
3. Poisson shot noise on the sum                                                     [temporal]
4. full well: charge above it spills partly into the 4 neighbours (blooming), the
   rest is drained; the pixel holds at most the full well
5. + Gaussian read noise σ_pre (e⁻, before the gain)                                 [temporal]
6. × K (DN/e⁻, ∝ ISO or webcam analog gain) + Gaussian σ_post (DN, after the gain),
   a share of it common to each row (row noise)                                      [temporal]
7. + black level + offset DSNU (DN), round, clip to [0, white level]                 [ADC]

Fixed-pattern noise is a property of the sensor: it comes from a counter-based hash of
(pixel column, pixel row, the body's ``fixed_pattern_seed``), so any crop of the frame
sees the same pattern. Two implementations draw the temporal noise
(:data:`camera_models.sensor_paths.SENSOR_PATHS`): fused Dr.Jit kernels
(:mod:`camera_models.sensor_kernel`, the default where Dr.Jit has its LLVM or CUDA backend)
and numpy (:func:`expose_numpy`, ``numpy.random.Generator(PCG64(seed))``, the step-by-step
reference). They draw from the same distributions (tests/camera_models/test_sensor_equivalence.py),
not the same numbers; each gives the same bytes for the same seed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray
from scipy import special

from camera_models.camera import SensorModel

__all__ = [
    "SensorModel",
    "SensorSettings",
    "bloom",
    "bloom_in_place",
    "cfa_channels",
    "clipped_normal_variance",
    "emva_saturation_e",
    "expose_numpy",
    "mosaic",
]

CFA_CHANNEL = {"R": 0, "G": 1, "B": 2}


def cfa_channels(cfa: str, x0: int, y0: int, height: int, width: int) -> NDArray[np.int8]:
    """Channel index (0 R, 1 G, 2 B) of each pixel of a crop, from the frame's 2×2 CFA pattern.

    ``cfa`` reads the 2×2 tile row by row from the frame's top-left pixel (e.g. ``RGGB``).
    """
    if len(cfa) != 4 or set(cfa) - set("RGB"):
        raise ValueError(f"cfa: expected a 2x2 pattern like 'RGGB', got {cfa!r}")
    tile = np.array([CFA_CHANNEL[ch] for ch in cfa], dtype=np.int8).reshape(2, 2)
    rows = (np.arange(height) + y0) % 2
    cols = (np.arange(width) + x0) % 2
    return tile[rows[:, None], cols[None, :]]


def _hash_uniform(x: NDArray[np.int64], y: NDArray[np.int64], seed: int, stream: int) -> NDArray[np.float64]:
    """Deterministic uniform (0, 1) numbers per pixel: splitmix64 of (x, y, seed, stream)."""
    with np.errstate(over="ignore"):
        z = (
            x.astype(np.uint64) * np.uint64(0x9E3779B97F4A7C15)
            ^ y.astype(np.uint64) * np.uint64(0xC2B2AE3D27D4EB4F)
            ^ np.uint64((seed * 1000003 + stream * 7919) & 0xFFFFFFFFFFFFFFFF)
        )
        z = z + np.uint64(0x9E3779B97F4A7C15)
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        z = z ^ (z >> np.uint64(31))
    return ((z >> np.uint64(11)).astype(np.float64) + 0.5) / float(1 << 53)


def _fixed_pattern(seed: int, x0: int, y0: int, height: int, width: int, stream: int) -> NDArray[np.float32]:
    """Standard-normal fixed-pattern values for the pixels of a crop (the same wherever the crop is)."""
    # float32 and in blocks of rows: a full 18 MP frame's pattern is 72 MB, its 64-bit
    # hashing temporaries would be several times that at once
    out = np.empty((height, width), dtype=np.float32)
    xs = np.arange(x0, x0 + width, dtype=np.int64)[None, :]
    for r0 in range(0, height, 256):
        ys = np.arange(y0 + r0, y0 + min(r0 + 256, height), dtype=np.int64)[:, None]
        u = _hash_uniform(
            np.broadcast_to(xs, (ys.shape[0], width)), np.broadcast_to(ys, (ys.shape[0], width)), seed, stream
        )
        out[r0 : r0 + ys.shape[0]] = math.sqrt(2.0) * special.erfinv(2.0 * u - 1.0)
    return out


@dataclass(frozen=True)
class SensorSettings:
    """How the sensor is run for one frame.

    Attributes
    ----------
    exposure_s
        Integration time, s.
    analog_gain
        Gain relative to base (ISO / base ISO, or the webcam's analog gain).
    """

    exposure_s: float
    analog_gain: float

    def validate(self) -> None:
        """Raise ValueError naming the field for impossible settings."""
        if not isinstance(self.exposure_s, int | float) or not math.isfinite(self.exposure_s) or self.exposure_s <= 0:
            raise ValueError(f"exposure_s: expected a time > 0 s, got {self.exposure_s!r}")
        if not math.isfinite(self.analog_gain) or self.analog_gain <= 0:
            raise ValueError(f"analog_gain: expected a gain > 0, got {self.analog_gain!r}")


def bloom(electrons: NDArray[np.float64], full_well_e: float, fraction: float, passes: int = 8) -> NDArray[np.float32]:
    """Clip charge at the full well, spilling ``fraction`` of the excess equally into the 4 neighbours.

    Repeated up to ``passes`` times so spilled charge can fill and overflow neighbours
    in turn; what does not spill goes to the anti-blooming drain. Charge spilled over the
    crop's edge is lost. Returns a new float32 array (e⁻).
    """
    e = electrons.astype(np.float32, copy=True)
    bloom_in_place(e, full_well_e, fraction, passes)
    return e


def bloom_in_place(e: NDArray[np.float32], full_well_e: float, fraction: float, passes: int = 8) -> None:
    """:func:`bloom` on a float32 array in place, computed only in the window that can change.

    Charge moves one pixel per pass, so only pixels within ``passes`` of one above the
    well can change: the spill is computed in that window (the pixels' bounding box grown
    by ``passes`` + 1, cut at the frame's edges), which gives the same values as the whole
    array and costs nothing when no well is full (one read of the array).
    """
    well = np.float32(full_well_e)
    if not e.max(initial=-np.inf) > well:  # most frames never fill a well
        return
    hot = e > well
    rows = np.flatnonzero(hot.any(axis=1))
    cols = np.flatnonzero(hot.any(axis=0))
    reach = passes + 1
    r0, r1 = max(rows[0] - reach, 0), min(rows[-1] + reach + 1, e.shape[0])
    c0, c1 = max(cols[0] - reach, 0), min(cols[-1] + reach + 1, e.shape[1])
    window = e[r0:r1, c0:c1]  # a view: the spill below writes into ``e``
    for _ in range(passes):
        if not window.max(initial=-np.inf) > well:
            return
        excess = np.clip(window - full_well_e, 0.0, None)
        window -= excess
        share = excess * (fraction / 4.0)
        window[1:, :] += share[:-1, :]
        window[:-1, :] += share[1:, :]
        window[:, 1:] += share[:, :-1]
        window[:, :-1] += share[:, 1:]
    np.minimum(window, full_well_e, out=window)


_ROWS = 256
"""Rows per block of the per-pixel work: a block of a full frame stays in the processor's cache."""


def _pixel_patterns(
    sensor: SensorModel, x0: int, y0: int, height: int, width: int
) -> tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.float32]]:
    """The sensor's fixed-pattern factors for a crop, read-only float32 (rows, columns):
    1 + PRNU, the dark-current factor max(1 + DSNU_I, 0), and the offset DSNU in DN."""
    key = (sensor.fixed_pattern_seed, sensor.prnu_fraction, sensor.dsnu_dark_current_fraction, sensor.dsnu_offset_DN)
    return _pixel_patterns_of(*key, x0, y0, height, width)


@lru_cache(maxsize=4)  # a whole T6 frame's three factors are 216 MB
def _pixel_patterns_of(
    seed: int, prnu: float, dsnu_dark: float, dsnu_offset: float, x0: int, y0: int, height: int, width: int
) -> tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.float32]]:
    f32 = np.float32
    gain = 1.0 + f32(prnu) * _fixed_pattern(seed, x0, y0, height, width, stream=1)
    dark = _fixed_pattern(seed, x0, y0, height, width, stream=2) * f32(dsnu_dark)
    dark += 1.0
    np.clip(dark, 0.0, None, out=dark)
    offset = f32(dsnu_offset) * _fixed_pattern(seed, x0, y0, height, width, stream=3)
    for a in (gain, dark, offset):
        a.setflags(write=False)
    return gain, dark, offset


def expose_numpy(
    mean_electrons: NDArray[np.float64],
    sensor: SensorModel,
    settings: SensorSettings,
    seed: int,
    x0: int = 0,
    y0: int = 0,
) -> NDArray[np.uint16]:
    """Raw frame (DN, uint16) from the mean photo-electrons of each pixel, by numpy: the
    reference implementation of the model, step by step as the module docstring lists them
    (two read-noise draws, numpy's Poisson sampler), and the path where Dr.Jit has no fast
    backend.

    Arguments as :func:`camera_models.sensor_paths.expose`.

    Notes
    -----
    float32 throughout, in blocks of :data:`_ROWS` rows where the arithmetic is per pixel.
    The temporal draws keep one order (every pixel's shot noise, then every pixel's
    read noise before the gain, then after it, then the row noise), and a generator's
    draws split into consecutive blocks equal one draw of the whole, so the bytes do not
    depend on the block size.
    """
    settings.validate()
    h, w = mean_electrons.shape
    rng = np.random.Generator(np.random.PCG64(seed))
    f32 = np.float32
    gain_fp, dark_fp, offset_fp = _pixel_patterns(sensor, x0, y0, h, w)
    dark_e = f32(sensor.dark_current_e_per_s * settings.exposure_s)
    electrons = np.empty((h, w), dtype=f32)
    for r in _blocks(h):
        mu = np.clip(mean_electrons[r], 0.0, None).astype(f32)
        mu *= gain_fp[r]
        mu += dark_fp[r] * dark_e
        electrons[r] = rng.poisson(mu)
    bloom_in_place(electrons, sensor.full_well_e, sensor.blooming_fraction)
    pre, post = sensor.read_noise_split()
    for r in _blocks(h):
        electrons[r] += rng.standard_normal(electrons[r].shape, dtype=f32) * f32(pre)
    K = sensor.K_DN_per_e(settings.analog_gain)
    row_sd = post * math.sqrt(sensor.row_noise_fraction)
    pix_sd = post * math.sqrt(1.0 - sensor.row_noise_fraction)
    dn = electrons
    for r in _blocks(h):
        dn[r] *= f32(K)
        dn[r] += rng.standard_normal(dn[r].shape, dtype=f32) * f32(pix_sd)
    row = rng.standard_normal((h, 1), dtype=f32) * f32(row_sd)
    top = min(sensor.white_level_DN, 2**sensor.adc_bits - 1)
    out = np.empty((h, w), dtype=np.uint16)
    for r in _blocks(h):
        block = dn[r]
        block += row[r]
        block += f32(sensor.black_level_DN)
        block += offset_fp[r]
        out[r] = np.clip(np.rint(block, out=block), 0, top, out=block)
    return out


def _blocks(rows: int) -> list[slice]:
    return [slice(r0, min(r0 + _ROWS, rows)) for r0 in range(0, rows, _ROWS)]


def mosaic(rgb: NDArray[np.float64], cfa: str, x0: int = 0, y0: int = 0) -> NDArray[np.float64]:
    """Pick each pixel's own channel from an (rows, columns, 3) image by the CFA."""
    ch = cfa_channels(cfa, x0, y0, 2, 2)
    out = np.empty(rgb.shape[:2], dtype=rgb.dtype)
    for dy in range(2):
        for dx in range(2):
            out[dy::2, dx::2] = rgb[dy::2, dx::2, ch[dy, dx]]
    return out


def clipped_normal_variance(mean: float, sd: float, clip: float) -> float:
    """Variance of min(X, clip) for X ~ N(mean, sd²) (the signal near saturation)."""
    a = (clip - mean) / sd
    phi, Phi = math.exp(-0.5 * a * a) / math.sqrt(2 * math.pi), 0.5 * (1 + math.erf(a / math.sqrt(2)))
    m1 = mean * Phi - sd * phi + clip * (1 - Phi)
    m2 = (mean**2 + sd**2) * Phi - sd * (mean + clip) * phi + clip**2 * (1 - Phi)
    return m2 - m1 * m1


def emva_saturation_e(sensor: SensorModel, analog_gain: float) -> float:
    """Saturation capacity as EMVA 1288 defines it: mean electrons where the temporal variance peaks.

    The output clips at ``sensor.saturation_e``; with shot and read noise the variance of
    the clipped signal peaks a little below that. Found from the model analytically
    (Gaussian approximation of the Poisson signal), independent of any simulation.
    """
    clip = sensor.saturation_e(analog_gain)
    read = sensor.read_noise_e(analog_gain)
    means = np.linspace(0.5 * clip, 1.2 * clip, 14001)
    var = [clipped_normal_variance(m, math.sqrt(m + read**2), clip) for m in means]
    return float(means[int(np.argmax(var))])
