"""Exposure control: manual settings (DSLR) or the webcam's automatic exposure loop.

Automatic exposure meters the whole frame: the mean over all pixels of the green
signal as a fraction of the clip level (clipped pixels count as 1), and steers the
product exposure × gain so that mean reaches ``target_mean``. Like consumer webcams it
raises the exposure time first (up to the frame-time limit), then the analog gain (in
the UVC gain code's integer steps), correcting a fraction ``ae_damping`` of the
logarithmic error each frame for ``ae_frames`` frames. In a mostly black frame the
mean stays far below target, so exposure and gain climb to their limits and the LEDs
saturate: the study's observation.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

from camera_models.camera import Camera

__all__ = ["ExposureSettings", "auto_exposure", "check_exposure_s", "manual_exposure"]


@dataclass(frozen=True)
class ExposureSettings:
    """Exposure of one frame.

    Attributes
    ----------
    exposure_s
        Integration time, s.
    analog_gain
        Gain relative to base.
    iso
        ISO (DSLR) or None.
    gain_code
        UVC gain code (webcam) or None.
    mode
        ``manual`` or ``auto``.
    history
        For auto exposure: (exposure_s, gain_code, metered mean) per simulated frame.
    """

    exposure_s: float
    analog_gain: float
    iso: float | None = None
    gain_code: int | None = None
    mode: str = "manual"
    history: tuple[tuple[float, int, float], ...] = field(default=())

    def to_dict(self) -> dict:
        """JSON-able form."""
        return {
            "mode": self.mode,
            "exposure_s": self.exposure_s,
            "analog_gain": self.analog_gain,
            "iso": self.iso,
            "gain_code": self.gain_code,
            "ae_history": [list(h) for h in self.history],
        }


def check_exposure_s(camera: Camera, exposure_s: float) -> float:
    """Validate an exposure time against the camera's range; return it as float."""
    try:
        t = float(exposure_s)
    except (TypeError, ValueError):
        t = float("nan")
    lo, hi = camera.exposure.min_exposure_s, camera.exposure.max_exposure_s
    if not math.isfinite(t) or t <= 0:
        raise ValueError(f"exposure_s: expected a time > 0 s, got {exposure_s!r}")
    if not lo * (1 - 1e-9) <= t <= hi * (1 + 1e-9):
        raise ValueError(f"exposure_s: expected {lo:g}-{hi:g} s for {camera.name}, got {exposure_s!r}")
    return t


def manual_exposure(
    camera: Camera, exposure_s: float | None = None, iso: float | None = None, gain_code: int | None = None
) -> ExposureSettings:
    """Fixed settings; defaults are the camera file's (T6: ISO 6400, 1/60 s as in the study)."""
    if camera.sensor.uses_iso:
        iso = camera.exposure.iso if iso is None else iso
        gain = camera.sensor.analog_gain(iso=iso)
    else:
        gain_code = camera.sensor.gain_code_min if gain_code is None else gain_code
        gain = camera.sensor.analog_gain(gain_code=gain_code)
    if exposure_s is None:
        exposure_s = camera.exposure.exposure_s if camera.exposure.exposure_s is not None else 1 / 30
    t = check_exposure_s(camera, exposure_s)
    return ExposureSettings(t, gain, float(iso) if iso is not None else None, gain_code, "manual")


def auto_exposure(camera: Camera, meter: Callable[[float, float], float]) -> ExposureSettings:
    """Run the camera's auto-exposure loop; ``meter(exposure_s, analog_gain)`` gives the frame's mean.

    ``meter`` returns the mean green signal over the full frame as a fraction of the clip
    level (0-1) for the given settings.
    """
    e, s = camera.exposure, camera.sensor
    if e.target_mean is None or e.ae_frames is None or e.ae_damping is None:
        raise ValueError(f"camera: {camera.name} has no automatic exposure")
    codes = (s.gain_code_min, s.gain_code_max) if not s.uses_iso else (None, None)
    g_max = s.analog_gain(gain_code=codes[1]) if codes[1] is not None else s.max_iso / s.base_iso
    t, code = min(e.max_exposure_s, max(e.min_exposure_s, 1 / 60)), codes[0]
    gain = s.analog_gain(gain_code=code) if code is not None else 1.0
    history = []
    for _ in range(e.ae_frames):
        m = max(meter(t, gain), 1e-9)
        history.append((t, code if code is not None else 0, m))
        total = t * gain * (e.target_mean / m) ** e.ae_damping
        total = min(max(total, e.min_exposure_s), e.max_exposure_s * g_max)
        t = min(max(total, e.min_exposure_s), e.max_exposure_s)
        wanted_gain = min(max(total / t, 1.0), g_max)
        if code is not None:
            span = s.gain_code_max - s.gain_code_min
            code = round(s.gain_code_min + (wanted_gain - 1.0) / (s.analog_gain_at_max_code - 1.0) * span)
            code = min(max(code, s.gain_code_min), s.gain_code_max)
            gain = s.analog_gain(gain_code=code)
        else:
            gain = wanted_gain
    return ExposureSettings(t, gain, None, code, "auto", tuple(history))
