"""Which implementation of the sensor model exposes a frame: the registry and the one entry point.

``drjit`` (fused kernels, :mod:`camera_models.sensor_kernel`) where Dr.Jit has its LLVM or CUDA
backend, else ``numpy`` (:func:`camera_models.sensor.expose_numpy`, the step-by-step reference).
"""

from __future__ import annotations

import logging
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from camera_models.camera import SensorModel
from camera_models.sensor import SensorSettings, expose_numpy
from camera_models.sensor_kernel import available, expose_drjit

__all__ = ["SENSOR_PATHS", "default_sensor_path", "expose"]


SENSOR_PATHS = {"drjit": expose_drjit, "numpy": expose_numpy}
"""The implementations of the sensor model: ``drjit`` (fused kernels,
:mod:`camera_models.sensor_kernel`) and ``numpy`` (the step-by-step reference). They draw from
the same distributions (tests/camera_models/test_sensor_equivalence.py), not the same numbers."""


def default_sensor_path() -> str:
    """``drjit`` where Dr.Jit has a fast backend (LLVM or CUDA), else ``numpy`` (logged once)."""
    if available():
        return "drjit"
    _log_numpy_fallback()
    return "numpy"


@lru_cache(maxsize=1)
def _log_numpy_fallback() -> None:
    logging.getLogger("beacon_sim").warning(
        "sensor: no fast Dr.Jit backend (libLLVM >= 16 or CUDA); using the slower numpy sensor path"
    )


def expose(
    mean_electrons: NDArray[np.float64],
    sensor: SensorModel,
    settings: SensorSettings,
    seed: int,
    x0: int = 0,
    y0: int = 0,
    *,
    path: str | None = None,
) -> NDArray[np.uint16]:
    """Raw frame (DN, uint16) from the mean photo-electrons of each pixel.

    Parameters
    ----------
    mean_electrons
        (rows, columns) mean photo-electrons of each pixel behind its own colour filter
        (use :func:`mosaic` to pick them from per-channel images), e⁻.
    sensor
        Sensor parameters.
    settings
        Exposure time and analog gain.
    seed
        Seed of the temporal noise (same seed and path → same bytes).
    x0, y0
        Frame position of the crop's top-left pixel (for the fixed pattern).
    path
        A key of :data:`SENSOR_PATHS`; default :func:`default_sensor_path`.
    """
    key = default_sensor_path() if path is None else path
    if key not in SENSOR_PATHS:
        raise ValueError(f"path: expected one of {', '.join(SENSOR_PATHS)}, got {path!r}")
    return SENSOR_PATHS[key](mean_electrons, sensor, settings, seed, x0, y0)
