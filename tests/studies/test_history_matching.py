"""History matching (studies.engine.calibration) against answers known without it.

The toy simulator has three inputs (x1 uniform on [0, 1], x2 uniform on [-1, 1], x3 log-uniform
on [0.1, 10]) and three outputs

    f1 = x1 + 0.3 x2,   f2 = sin(1.5 x2) + 0.2 x1 log10(x3),   f3 = exp(-0.5 log10(x3)) + 0.3 x1,

plus Gaussian run noise of known sd 0.01, a fixed function of the point (so a run is
reproducible and a resumed match sees the same runs). Observations are the true outputs at
x* = (0.4, 0.3, 2.0) with observation and discrepancy sd 0.04 each. With the true function in
place of the emulators the non-implausible region {x: max_j |f_j(x) - z_j| / sd_j <= 3}
(sd_j² = 0.01² + 0.04² + 0.04²) is computed on a 60³ grid of the unit cube: ~1.8 % of the space.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from studies.engine.calibration import (
    Input,
    InputSpace,
    Observation,
    Settings,
    closest_points,
    combine,
    diagnose,
    fit_emulator,
    from_json,
    history_match,
    implausibility,
    nroy_mask,
    nroy_sample,
    observation_shares,
    required_discrepancy_var,
    to_json,
    write_figures,
)
from studies.engine.calibration.design import sobol
from studies.engine.calibration.plots import FIGURES, ranked_inputs
from studies.engine.unknowns import load_unknowns

SPACE = InputSpace((Input("x1", 0.0, 1.0), Input("x2", -1.0, 1.0), Input("x3", 0.1, 10.0, log=True)))
NOISE_SD = 0.01
SD = 0.04
X_STAR = {"x1": 0.4, "x2": 0.3, "x3": 2.0}
FAST = {"n_per_wave": 30, "n_restarts": 2}


def truth(x1, x2, x3):
    u3 = np.log10(x3)
    return np.stack([x1 + 0.3 * x2, np.sin(1.5 * x2) + 0.2 * x1 * u3, np.exp(-0.5 * u3) + 0.3 * x1], axis=-1)


def simulate(values, *, noise_seed=0, fail_every=0):
    x = np.array([[v["x1"], v["x2"], v["x3"]] for v in values])
    f = truth(x[:, 0], x[:, 1], x[:, 2])
    for i, row in enumerate(x):  # noise: a function of the point and the seed, so runs are reproducible
        rng = np.random.default_rng([noise_seed, *np.frombuffer(row.tobytes(), dtype=np.uint32).tolist()])
        f[i] += rng.normal(0.0, NOISE_SD, 3)
    if fail_every:
        f[::fail_every, 1] = np.nan  # a failed run
    return f


Z_STAR = truth(0.4, 0.3, 2.0)


def observations(z=Z_STAR):
    return tuple(Observation(f"f{j + 1}", float(z[j]), SD**2, SD**2, "toy: known", "toy: stated") for j in range(3))


def unit_to_natural(q):
    """The toy's inputs at unit points, written out independently of InputSpace."""
    return q[:, 0], -1.0 + 2.0 * q[:, 1], 10.0 ** (-1.0 + 2.0 * q[:, 2])


@pytest.fixture(scope="module")
def analytic():
    n = 60
    g = (np.arange(n) + 0.5) / n
    q = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    f = truth(*unit_to_natural(q))
    inside = np.max(np.abs(f - Z_STAR) / math.sqrt(NOISE_SD**2 + 2 * SD**2), axis=1) <= 3.0
    return q, inside


@pytest.fixture(scope="module")
def planted():
    return history_match(simulate, SPACE, observations(), settings=Settings(seed=0, **FAST))


def check_planted(result, analytic):
    q, inside = analytic
    true_fraction = inside.mean()
    assert result.stopped in ("stopped shrinking", "max waves") and len(result.waves) >= 3
    assert nroy_mask(result, SPACE.to_unit([X_STAR]))[0]
    # extent: the fraction within 15 % of the analytic one; ≥ 85 % of the analytic region kept and
    # what is kept outside it < 10 % of its size (emulator error at the boundary is a few 0.01).
    assert abs(result.nroy_fraction / true_fraction - 1) < 0.15
    kept = nroy_mask(result, q)
    assert kept[inside].mean() > 0.85
    assert kept[~inside].sum() < 0.10 * inside.sum()
    emulated = q[kept]
    # bounds, in unit coordinates (grid step 1/60): of the grid points the emulated NROY keeps
    # against the analytic region's, extremes within 0.06 (the region's tips are thin: one
    # wave's emulator error there trims them) and 1 %/99 % quantiles within 0.04; the 5-95 %
    # quantiles of the NROY sample (the reference Sobol' points kept) within 0.03
    np.testing.assert_allclose(emulated.min(0), q[inside].min(0), atol=0.06)
    np.testing.assert_allclose(emulated.max(0), q[inside].max(0), atol=0.06)
    for p in (1, 99):
        np.testing.assert_allclose(np.percentile(emulated, p, 0), np.percentile(q[inside], p, 0), atol=0.04)
    for p in (5, 95):
        np.testing.assert_allclose(np.percentile(result.nroy_points, p, 0), np.percentile(q[inside], p, 0), atol=0.03)


def test_planted_region_is_recovered(planted, analytic):
    check_planted(planted, analytic)
    assert 0.015 < analytic[1].mean() < 0.022  # the toy is what the docstring says


def test_the_nroy_sample_lies_in_the_planted_region(planted, analytic):
    """nroy.csv's points: n of them, each passing every wave, nearly all inside the analytic region, found
    at the NROY fraction's rate, the same ones on every call."""
    points, drawn = nroy_sample(planted, 256)
    assert points.shape == (256, 3) and nroy_mask(planted, points).all()
    f = truth(*unit_to_natural(points))
    inside = np.max(np.abs(f - Z_STAR) / math.sqrt(NOISE_SD**2 + 2 * SD**2), axis=1) <= 3.0
    assert inside.mean() > 0.85  # the emulators' boundary error, as check_planted allows
    assert abs(256 / drawn / planted.nroy_fraction - 1) < 0.3  # drawn in 4096-point blocks: coarse
    again, _ = nroy_sample(planted, 256)
    np.testing.assert_array_equal(points, again)
    few, _ = nroy_sample(planted, 10, max_points=4096)
    assert len(few) == 10 and np.array_equal(few, points[:10])
    with pytest.raises(ValueError, match=r"n: expected an integer >= 1, got 0"):
        nroy_sample(planted, 0)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_planted_region_other_seeds(seed, analytic):
    result = history_match(
        lambda v: simulate(v, noise_seed=seed), SPACE, observations(), settings=Settings(seed=seed, **FAST)
    )
    check_planted(result, analytic)


def test_waves_shrink_and_emulators_are_diagnosed(planted):
    fractions = [w.nroy_fraction for w in planted.waves]
    assert fractions == sorted(fractions, reverse=True) and fractions[0] < 0.05
    for wave in planted.waves:
        assert len(wave.design) == 30 and np.all((wave.design >= 0) & (wave.design <= 1))
        assert [d.kind for d in wave.loo] == ["loo"] * 3
        pooled = np.concatenate([d.standardised_errors for d in wave.loo])
        assert 0.85 <= np.mean(np.abs(pooled) <= 1.96) <= 1.0
        # the white-noise term finds the simulator's run noise (sd 0.01) on every output
        assert all(0.004 < e.noise_var**0.5 < 0.02 for e in wave.emulators) or wave.index == 1
    # the designs after the first lie in the region the earlier waves left
    later = planted.waves[1]
    assert nroy_mask(type(planted)(**{**planted.__dict__, "waves": planted.waves[:1]}), later.design).all()


def test_loo_coverage_is_nominal():
    """128 Sobol' runs over the whole space, pooled over the 3 outputs (384 LOO errors: the
    binomial sd of a 95 % coverage is 1.1 %), and 128 held-out runs."""
    q = sobol(128, 3, seed=11)
    y = simulate(SPACE.values(q), noise_seed=5)
    q_val = sobol(128, 3, seed=12)
    y_val = simulate(SPACE.values(q_val), noise_seed=6)
    loo_e, val_e = [], []
    for j in range(3):
        em = fit_emulator(SPACE.features(q), y[:, j], output=f"f{j + 1}", n_restarts=2, seed=j)
        loo_e.append(diagnose(em).standardised_errors)
        val_e.append(diagnose(em, SPACE.features(q_val), y_val[:, j]).standardised_errors)
    loo_e, val_e = np.concatenate(loo_e), np.concatenate(val_e)
    assert abs(np.mean(np.abs(loo_e) <= 1.959964) - 0.95) <= 0.05
    assert abs(np.mean(np.abs(loo_e) <= 1.0) - 0.6827) <= 0.10
    assert abs(np.mean(np.abs(val_e) <= 1.959964) - 0.95) <= 0.05


def test_nothing_fits_names_the_observation_and_its_discrepancy():
    """f3 observed at 3.0, above anything the toy makes (its largest value, at x1 = 1 and
    x3 = 0.1, is e^0.5 + 0.3): NROY is empty after one wave and only f3 is to blame, with
    discrepancy sd sqrt(((3 - f3_max) / 3)² - obs_var - run noise var)."""
    z = Z_STAR.copy()
    z[2] = 3.0
    result = history_match(simulate, SPACE, observations(z), settings=Settings(seed=0, **FAST))
    assert result.stopped == "nroy empty" and result.nroy_fraction == 0 and len(result.waves) == 1
    assert len(result.nroy_points) == 0 and result.nroy_values() == []
    needs = {d.observation: d for d in result.discrepancy}
    assert [name for name, d in needs.items() if d.rules_out_alone] == ["f3"]
    assert [name for name, d in needs.items() if d.alone_sd > d.stated_sd] == ["f3"]
    f3_max = math.exp(0.5) + 0.3
    expected = math.sqrt(((3.0 - f3_max) / 3.0) ** 2 - SD**2 - NOISE_SD**2)
    assert needs["f3"].alone_sd == pytest.approx(expected, rel=0.03)
    assert needs["f1"].alone_sd == 0.0 and needs["f2"].alone_sd == 0.0
    # jointly (at the best point) f3 needs at least what it needs alone
    assert needs["f3"].joint_sd >= needs["f3"].alone_sd
    # the closest points: the least implausible first, every one above the cut-off, near f3's best corner
    # (x3 = 0.1, x1 = 1: f3 = e^0.5 + 0.3 is as near 3 as the toy gets)
    near, worst = closest_points(result, 8)
    assert near.shape == (8, 3) and (np.diff(worst) >= 0).all() and (worst > 3.0).all()
    x1, _, x3 = unit_to_natural(near)
    assert (x3 < 0.5).all() and (x1 > 0.5).all()
    with pytest.raises(ValueError, match=r"n: expected an integer >= 1"):
        closest_points(result, 0)


def test_same_seed_same_json_bytes_and_round_trip():
    settings = Settings(
        seed=4, n_per_wave=20, n_validation=4, min_waves=2, max_waves=2, n_reference=2**12, n_restarts=1
    )

    def run():
        return to_json(history_match(lambda v: simulate(v, fail_every=7), SPACE, observations(), settings=settings))

    text = run()
    assert run() == text
    doc = json.loads(text, parse_constant=lambda c: pytest.fail(f"non-finite {c} in the JSON"))
    assert doc["waves"][0]["outputs"][0][1] is None  # the failed run is null, not NaN
    assert len(doc["waves"][0]["validation"]) == 3
    assert to_json(from_json(text)) == text  # emulators rebuilt from the file predict the same


def test_resume_continues_where_it_stopped():
    settings = Settings(seed=2, n_per_wave=20, min_waves=3, max_waves=3, n_reference=2**12, n_restarts=1)
    straight = history_match(simulate, SPACE, observations(), settings=settings)
    written = []
    first = history_match(
        simulate, SPACE, observations(), settings=Settings(**{**settings.__dict__, "min_waves": 2, "max_waves": 2}),
        on_wave=lambda r: written.append(to_json(r)),
    )  # fmt: skip
    assert len(written) == 2 and len(first.waves) == 2
    resumed = history_match(simulate, SPACE, observations(), settings=settings, resume=from_json(written[-1]))
    assert to_json(resumed) == to_json(straight)
    with pytest.raises(ValueError, match="resume"):
        history_match(simulate, SPACE, observations(), settings=Settings(seed=3), resume=first)


def test_implausibility_and_combination_by_hand():
    obs = (Observation("a", 1.0, 0.5, 0.5), Observation("b", 0.0, 1.0, 0.0), Observation("c", 2.0, 0.0, 1.0))
    mean = np.array([[3.0, 3.0, 2.0], [1.0, 0.0, 5.0]])
    var = np.array([[2.0, 3.0, 3.0], [0.0, 0.0, 0.0]])
    per = implausibility(mean, var, obs)
    np.testing.assert_allclose(per, [[2 / math.sqrt(3), 1.5, 0.0], [0.0, 0.0, 3.0]])
    np.testing.assert_allclose(combine(per, order=1), [1.5, 3.0])
    np.testing.assert_allclose(combine(per, order=2), [2 / math.sqrt(3), 0.0])
    np.testing.assert_allclose(combine(per, order=3), [0.0, 0.0])
    # required discrepancy brings I to exactly the cut-off
    d = required_discrepancy_var(mean, var, obs, cutoff=3.0)
    np.testing.assert_allclose(d[1], [0.0, 0.0, 1.0])  # c: stated disc_var 1 puts I at exactly 3
    d = required_discrepancy_var(np.array([[10.0, 0, 2]]), np.zeros((1, 3)), obs, cutoff=3.0)
    assert d[0, 0] == pytest.approx(81 / 9 - 0.5)
    with pytest.raises(ValueError, match="order"):
        combine(per, order=4)


def test_bounds_count_only_their_shortfall():
    """``at_least`` / ``at_most`` observations: 0 on their side, the equality's value past the bound."""
    obs = (Observation("lo", 13.0, 1.0, 3.0, kind="at_least"), Observation("hi", 0.0, 0.0, 4.0, kind="at_most"))
    mean = np.array([[20.0, -5.0], [9.0, 6.0], [13.0, 0.0]])
    per = implausibility(mean, np.zeros((3, 2)), obs)
    np.testing.assert_allclose(per, [[0.0, 0.0], [4 / 2, 6 / 2], [0.0, 0.0]])
    d = required_discrepancy_var(mean, np.zeros((3, 2)), obs, cutoff=2.0)
    np.testing.assert_allclose(d, [[0.0, 0.0], [4 - 1.0, 9.0], [0.0, 0.0]])
    assert Observation.from_json(obs[0].to_json()) == obs[0]
    with pytest.raises(ValueError, match="kind"):
        Observation("x", 1.0, 1.0, 1.0, kind="between")


def test_a_bound_keeps_the_region_on_its_side():
    """History match of y = x on [0, 1] to "y at least 0.6": NROY is x >= ~0.6 (emulator error aside)."""
    space = InputSpace((Input("x", 0.0, 1.0),))
    observation = Observation("y", 0.6, 0.0, 0.02**2, kind="at_least")
    result = history_match(
        lambda values: np.array([[v["x"]] for v in values]),
        space,
        [observation],
        settings=Settings(n_per_wave=8, min_waves=2, max_waves=2, n_reference=1024, n_restarts=1),
    )
    x = result.nroy_points[:, 0]
    assert x.min() == pytest.approx(0.6 - 3 * 0.02, abs=0.02) and x.max() == pytest.approx(1.0, abs=1e-3)


def test_inputs_map_like_the_unknowns_registry():
    q = np.array([[0.0, 0.5, 1.0], [0.25, 0.75, 0.5]])
    values = SPACE.values(q)
    assert values[0] == {"x1": 0.0, "x2": 0.0, "x3": 10.0}
    assert values[1]["x3"] == pytest.approx(1.0)  # log scale: the middle of 0.1-10 is 1
    np.testing.assert_allclose(SPACE.to_unit(values), q)
    space = InputSpace((Input("a", 1.0, 2.0), Input("paper", choices=("black", "white", "grey"))))
    np.testing.assert_array_equal(space.features([[0.5, 0.1], [0.5, 0.5], [0.5, 0.99]])[:, 1:], np.eye(3))
    assert [v["paper"] for v in space.values([[0, 0.1], [0, 0.5], [0, 1.0]])] == ["black", "white", "grey"]
    registry = load_unknowns()
    from_registry = InputSpace.from_unknowns(registry)
    assert set(from_registry.names) == {n for n, u in registry.items() if u.kind != "fixed"}
    for inp in from_registry.inputs:
        u = registry[inp.name]
        assert inp.log == (u.kind == "loguniform") and inp.categorical == (u.kind == "choice")


def test_each_observations_share_of_the_space_is_known():
    """y1 = x1 observed 'at most 0.3' rules out ~70 % alone; y2 = x2 + 1 observed at 10 (impossible) rules
    out everything alone, and without it the space left is y1's 30 %."""
    space = InputSpace((Input("x1", 0.0, 1.0), Input("x2", 0.0, 1.0)))
    obs = [Observation("y1", 0.3, 0.0, 0.01**2, kind="at_most"), Observation("y2", 10.0, 0.0, 0.01**2)]
    result = history_match(
        lambda values: np.array([[v["x1"], v["x2"] + 1.0] for v in values]),
        space,
        obs,
        settings=Settings(n_per_wave=16, min_waves=1, max_waves=1, n_reference=2048, n_restarts=1),
    )
    alone, without = observation_shares(result)
    assert alone[0] == pytest.approx(0.7 - 3 * 0.01, abs=0.03) and alone[1] == 1.0
    assert without[1] == pytest.approx(0.3 + 3 * 0.01, abs=0.03) and without[0] == 0.0


def test_the_constraining_input_is_ranked_first():
    """Only x2 enters the output: its 1-D implausibility profile rises, the others' stay flat."""
    result = history_match(
        lambda values: np.array([[v["x2"] ** 2] for v in values]),
        SPACE,
        [Observation("y", 0.25, 0.0, 0.05**2)],
        settings=Settings(n_per_wave=12, min_waves=1, max_waves=1, n_reference=1024, n_restarts=1),
    )
    assert ranked_inputs(result)[0] == 1


def test_figures_have_deterministic_bytes(planted, tmp_path):
    first = write_figures(planted, tmp_path / "a")
    second = write_figures(planted, tmp_path / "b")
    assert [p.name for p in first] == [f"{name}.png" for name in FIGURES]
    for a, b in zip(first, second, strict=True):
        assert a.read_bytes() == b.read_bytes() and a.stat().st_size > 5000
