"""The Dr.Jit sensor kernels draw from the same distributions as the numpy reference path.

Byte identity between the two is not the contract (issue 24): each is checked against the
model's own answer (Poisson probabilities; the EMVA 1288 photon-transfer relation
σ²_y = K²(μ_e + σ_pre²) + σ_post² + 1/12) and against the other (means and temporal
variances within 1 %, dark-frame histograms by a two-sample χ² test). Each check is also
run on a planted change (read noise +10 %, no shot noise, a Poisson mean 5 % off) and must
reject it, so none of them can pass whatever the kernels do.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy import stats

from camera_models.camera import load_camera
from camera_models.sensor import SensorSettings
from camera_models.sensor_kernel import INVERSION_MAX_E, available, poisson
from camera_models.sensor_paths import expose
from studies.experiments.equivalence import PTC_SHAPE as SHAPE
from studies.experiments.equivalence import dark_histogram_p, photon_transfer

pytestmark = pytest.mark.skipif(not available(), reason="no fast Dr.Jit backend (libLLVM >= 16 or CUDA)")

CAMERAS = {
    "canon-t6-18mm": ({"iso": 100}, {"iso": 6400}),
    "logitech-c270": ({"gain_code": 0}, {"gain_code": 255}),
    "spedal-920": ({"gain_code": 0}, {"gain_code": 255}),
}


def poisson_fit_p(counts: np.ndarray, mean: float) -> float:
    """p-value of a χ² goodness-of-fit test of integer counts against Poisson(mean), bins of ≥ 5 expected."""
    n = counts.size
    top = int(stats.poisson.ppf(1 - 1e-9, mean)) + 1
    k = np.arange(top + 1)
    expected = n * stats.poisson.pmf(k, mean)
    expected[-1] += n * stats.poisson.sf(top, mean)
    observed = np.bincount(np.minimum(counts.astype(np.int64), top), minlength=top + 1).astype(float)
    # merge bins from both tails inward until each expects at least 5
    edges, acc_o, acc_e = [], 0.0, 0.0
    for o, e in zip(observed, expected, strict=True):
        acc_o, acc_e = acc_o + o, acc_e + e
        if acc_e >= 5:
            edges.append((acc_o, acc_e))
            acc_o = acc_e = 0.0
    if acc_e > 0 and edges:
        o, e = edges.pop()
        edges.append((o + acc_o, e + acc_e))
    obs, exp = np.array(edges).T
    if len(obs) < 2:  # all mass in one bin: nothing to test beyond the total
        return 1.0
    return float(stats.chisquare(obs, exp * obs.sum() / exp.sum()).pvalue)


@pytest.mark.parametrize("mean", [0.003, 0.7, 5.0, INVERSION_MAX_E - 0.1, INVERSION_MAX_E + 0.1, 300.0])
def test_poisson_counts_follow_the_poisson_law(mean):
    counts = poisson(np.full(400_000, mean, np.float32), seed=5)
    assert np.all(counts == np.rint(counts)) and counts.min() >= 0
    assert poisson_fit_p(counts, mean) > 1e-3
    assert counts.mean() == pytest.approx(mean, rel=6 * math.sqrt(1 / (mean * counts.size)))


@pytest.mark.parametrize("mean", [0.003, 5.0, 300.0])
def test_the_poisson_check_rejects_a_mean_5_percent_off(mean):
    counts = poisson(np.full(400_000, mean * 1.05, np.float32), seed=5)
    if mean < 0.01:  # 0.003 × 5 %: too few non-zero counts to see; check the rate instead
        assert abs(counts.mean() / mean - 1) > 0.03
    else:
        assert poisson_fit_p(counts, mean) < 1e-6


def test_poisson_is_deterministic_and_seeded():
    m = np.full(10_000, 3.0, np.float32)
    assert np.array_equal(poisson(m, 1), poisson(m, 1))
    assert not np.array_equal(poisson(m, 1), poisson(m, 2))


def _levels(sensor, gain: float) -> list[float]:
    clip = sensor.saturation_e(gain)
    return [0.0, 0.002 * clip, 0.05 * clip, 0.5 * clip]


def _settings(cam, setting: dict) -> SensorSettings:
    return SensorSettings(0.01, cam.sensor.analog_gain(**setting))


def _compare_paths(sensor, settings, levels, drjit_sensor=None) -> list[tuple[float, float, float]]:
    """Per level: (relative mean difference, relative variance difference, expected relative SE of the variance)."""
    out = []
    for level in levels:
        m_n, v_n = photon_transfer(sensor, settings, level, "numpy")
        m_d, v_d = photon_transfer(drjit_sensor or sensor, settings, level, "drjit")
        out.append((abs(m_d - m_n) / max(m_n, 1.0), abs(v_d / v_n - 1.0), math.sqrt(2.0 / (SHAPE[0] * SHAPE[1]))))
    return out


@pytest.mark.parametrize("name", list(CAMERAS))
@pytest.mark.parametrize("which", [0, 1], ids=["base-gain", "high-gain"])
def test_photon_transfer_of_both_paths_agrees_within_1_percent(name, which):
    cam = load_camera(name)
    settings = _settings(cam, CAMERAS[name][which])
    for rel_mean, rel_var, _se in _compare_paths(cam.sensor, settings, _levels(cam.sensor, settings.analog_gain)):
        assert rel_mean < 0.01 and rel_var < 0.01, (rel_mean, rel_var)


@pytest.mark.parametrize("name", list(CAMERAS))
def test_photon_transfer_follows_the_emva_model(name):
    """Temporal variance against K²(μ + μ_dark + σ_pre²) + σ_post² + 1/12 (quantisation), where the
    noise spans several DN (so the 1/12 term holds) and the signal stays 4σ clear of 0 and the clip."""
    cam = load_camera(name)
    s = cam.sensor
    settings = _settings(cam, CAMERAS[name][1])
    K = s.K_DN_per_e(settings.analog_gain)
    pre, post = s.read_noise_split()
    checked = 0
    for level in _levels(s, settings.analog_gain)[:3]:
        dark = s.dark_current_e_per_s * settings.exposure_s  # the DSNU factor averages to ~1 (clipped at 0)
        expected = K**2 * (level * 1.0 + dark + pre**2) + post**2 + 1.0 / 12.0
        mean_dn = s.black_level_DN + K * (level + dark)
        top = min(s.white_level_DN, 2**s.adc_bits - 1)
        if math.sqrt(expected) < 2.0 or not 4 * math.sqrt(expected) < mean_dn < top - 4 * math.sqrt(expected):
            continue
        _mean, var = photon_transfer(s, settings, level, "drjit")
        assert var == pytest.approx(expected, rel=0.02), (level, var, expected)
        checked += 1
    assert checked >= 1


def test_photon_transfer_check_fails_on_planted_changes():
    """Read noise +10 % or no shot noise on the kernel side: the 1 % comparison above must fail."""
    cam = load_camera("canon-t6-18mm")
    s = cam.sensor
    settings = _settings(cam, {"iso": 6400})
    louder = _louder(s)
    dark = _compare_paths(s, settings, [0.0], drjit_sensor=louder)[0]
    assert dark[1] > 0.01
    # no shot noise: a sensor whose Poisson step is replaced by the mean (electrons = round(μ))
    from camera_models import sensor_kernel

    real = sensor_kernel._poisson_counts
    try:
        sensor_kernel._poisson_counts = _no_shot_noise
        bright = _compare_paths(s, settings, [0.05 * s.saturation_e(settings.analog_gain)])[0]
    finally:
        sensor_kernel._poisson_counts = real
    assert bright[1] > 0.01


def _no_shot_noise(lam, seed):
    import drjit as dr

    counts = dr.round(lam)
    dr.eval(counts)
    return counts, np.zeros(0, np.uint32), np.zeros(0, np.float32)


def _louder(sensor, factor: float = 1.1):
    """The sensor with both read-noise figures × ``factor`` (a planted change)."""
    return dataclasses.replace(
        sensor,
        read_noise_e_at_base=sensor.read_noise_e_at_base * factor,
        read_noise_e_at_high_gain=sensor.read_noise_e_at_high_gain * factor,
    )


@pytest.mark.parametrize(("name", "setting"), [("canon-t6-18mm", {"iso": 6400}), ("logitech-c270", {"gain_code": 255})])
def test_dark_frame_histograms_agree(name, setting):
    """Dark frames (exposure 1/30 s, no light) of the two paths: two-sample χ² p > 0.001;
    with read noise +10 % on one side the same test gives p < 10⁻⁶. One pixel per row is
    compared (a frame of 2 columns, the first taken): pixels of one row share its row noise,
    which the test's independent-samples assumption does not allow."""
    cam = load_camera(name)
    s = cam.sensor
    settings = SensorSettings(1 / 30, s.analog_gain(**setting))
    dark = np.zeros((400_000, 2), np.float32)

    def frame(sensor, path, seed=7):
        return expose(dark, sensor, settings, seed, path=path)[:, 0].astype(np.int64)

    a, b = frame(s, "numpy"), frame(s, "drjit")
    assert dark_histogram_p(b, frame(s, "drjit", seed=8)) > 1e-3  # independent pixels and seeds
    p = dark_histogram_p(a, b)
    print(name, "dark-frame χ² p =", p)
    assert p > 1e-3
    louder = _louder(s)
    assert dark_histogram_p(a, frame(louder, "drjit")) < 1e-6


def test_blooming_and_clipping_agree_between_paths():
    """Cores far past the full well: the same clipped and bloomed pixels (mean DN per pixel within 1 %)."""
    cam = load_camera("canon-t6-18mm")
    s = cam.sensor
    settings = SensorSettings(0.01, 1.0)
    mu = np.zeros((64, 64), np.float32)
    mu[30:34, 30:34] = 20 * s.full_well_e
    frames = {p: np.mean([expose(mu, s, settings, k, path=p) for k in range(8)], axis=0) for p in ("numpy", "drjit")}
    hot = frames["numpy"] > s.black_level_DN + 50
    assert hot.sum() > 16  # charge spilled beyond the 4×4 core
    assert np.array_equal(hot, frames["drjit"] > s.black_level_DN + 50)
    assert np.allclose(frames["drjit"][hot], frames["numpy"][hot], rtol=0.01)


def test_kernel_path_is_deterministic():
    cam = load_camera("logitech-c270")
    mu = np.random.default_rng(0).uniform(0, 50, (120, 160)).astype(np.float32)
    settings = SensorSettings(0.01, 2.0)
    a = expose(mu, cam.sensor, settings, 3, path="drjit")
    assert np.array_equal(a, expose(mu, cam.sensor, settings, 3, path="drjit"))
    assert not np.array_equal(a, expose(mu, cam.sensor, settings, 4, path="drjit"))
