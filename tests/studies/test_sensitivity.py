"""The sensitivity engine (studies.engine.sensitivity) against answers known without it.

The Ishigami function (Ishigami & Homma 1990) f = sin x1 + a sin² x2 + b x3⁴ sin x1, with a = 7,
b = 0.1 and every input uniform on [-π, π], has closed-form Sobol' indices (Sobol' & Levitan 1999;
Marrel et al. 2009): with

    V  = a²/8 + b π⁴/5 + b² π⁸/18 + 1/2     (the variance)
    V1 = (1 + b π⁴/5)² / 2,   V2 = a²/8,   V3 = 0,   V13 = 8 b² π⁸ / 225  (x1 with x3),

S1_i = V_i / V, ST1 = (V1 + V13) / V, ST2 = V2 / V, ST3 = V13 / V. The tests compute these from the
closed forms, independently of SALib.
"""

from __future__ import annotations

import itertools
import json
import math

import numpy as np
import pytest

from studies.engine.calibration.design import sobol as sobol_points
from studies.engine.calibration.inputs import Input, InputSpace
from studies.engine.sensitivity import EmulatedModel, Sobol, aliased_inputs, emulate, explain, morris, sobol
from studies.engine.unknowns import load_unknowns, nominal

A, B = 7.0, 0.1
ISHIGAMI = InputSpace(tuple(Input(f"x{i}", -math.pi, math.pi) for i in (1, 2, 3)))


def as_array(space: InputSpace, q: np.ndarray) -> np.ndarray:
    """The space's values at unit points q, as an (n, d) array: the mapping the registry's runs use."""
    return np.array([[v[name] for name in space.names] for v in space.values(q)], dtype=float)


def ishigami(q: np.ndarray) -> np.ndarray:
    x = as_array(ISHIGAMI, q)
    return np.sin(x[:, 0]) + A * np.sin(x[:, 1]) ** 2 + B * x[:, 2] ** 4 * np.sin(x[:, 0])


def analytic_ishigami(a: float = A, b: float = B) -> tuple[np.ndarray, np.ndarray]:
    pi = math.pi
    v = a**2 / 8 + b * pi**4 / 5 + b**2 * pi**8 / 18 + 0.5
    v1 = 0.5 * (1 + b * pi**4 / 5) ** 2
    v2 = a**2 / 8
    v13 = 8 * b**2 * pi**8 / 225
    return np.array([v1, v2, 0.0]) / v, np.array([v1 + v13, v2, v13]) / v


def test_the_analytic_values_are_the_published_ones():
    s1, st = analytic_ishigami()
    np.testing.assert_allclose(s1, [0.3139, 0.4424, 0.0], atol=1e-4)
    np.testing.assert_allclose(st, [0.5576, 0.4424, 0.2437], atol=1e-4)


def test_sobol_indices_of_ishigami_match_the_closed_forms():
    r = sobol(ishigami, ISHIGAMI, n=4096, seed=0)
    s1, st = analytic_ishigami()
    assert r.inputs == ("x1", "x2", "x3")
    assert r.runs == 4096 * (3 + 2) and r.n == 4096 and r.held == () and r.s2 == ()
    np.testing.assert_allclose(r.s1[:2], s1[:2], rtol=0.05)
    assert abs(r.s1[2]) < 0.02
    np.testing.assert_allclose(r.st, st, rtol=0.05)
    assert all(0 < c < 0.1 for c in (*r.s1_conf, *r.st_conf))
    assert r.variance == pytest.approx(analytic_variance(), rel=0.05)
    assert r.ranked("s1") == ("x2", "x1", "x3") and r.ranked("st") == ("x1", "x2", "x3")


def analytic_variance(a: float = A, b: float = B) -> float:
    return a**2 / 8 + b * math.pi**4 / 5 + b**2 * math.pi**8 / 18 + 0.5


def test_second_order_indices_find_the_x1_x3_interaction():
    r = sobol(ishigami, ISHIGAMI, n=2048, seed=0, second_order=True)
    assert r.runs == 2048 * (2 * 3 + 2)
    pairs = {(a, b): v for a, b, v, _ in r.s2}
    assert set(pairs) == {("x1", "x2"), ("x1", "x3"), ("x2", "x3")}
    v13 = 8 * B**2 * math.pi**8 / 225 / analytic_variance()
    assert pairs[("x1", "x3")] == pytest.approx(v13, abs=0.05)
    assert abs(pairs[("x1", "x2")]) < 0.05 and abs(pairs[("x2", "x3")]) < 0.05


def test_a_subset_holds_the_others_at_their_nominal():
    seen = []

    def model(q):
        seen.append(q)
        return ishigami(q)

    r = sobol(model, ISHIGAMI, inputs=["x2", "x1"], nominal={"x3": 0.0, "not_in_space": 1}, n=1024, seed=3)
    assert r.inputs == ("x1", "x2")  # the space's order
    assert r.held == (("x3", 0.5),)
    assert seen[0].shape == (1024 * 4, 3) and np.all(seen[0][:, 2] == 0.5)
    # x3 = 0: f = sin x1 + a sin² x2, additive: S1 = ST = (1/2, a²/8) / (1/2 + a²/8)
    expected = np.array([0.5, A**2 / 8]) / (0.5 + A**2 / 8)
    np.testing.assert_allclose(r.s1, expected, rtol=0.05, atol=0.01)
    np.testing.assert_allclose(r.st, expected, rtol=0.05, atol=0.01)
    centre = sobol(ishigami, ISHIGAMI, inputs=["x1"], n=64, seed=3)
    assert centre.held == (("x2", 0.5), ("x3", 0.5))


def planted(q: np.ndarray) -> np.ndarray:
    """Strong a, weaker b (non-linear), c inert, d small with a."""
    return 10 * q[:, 0] + 3 * q[:, 1] ** 2 + 0 * q[:, 2] + q[:, 0] * q[:, 3]


PLANTED = InputSpace(tuple(Input(name, 0.0, 1.0) for name in "abcd"))


def test_morris_ranks_a_planted_inert_input_last_and_the_strongest_first():
    r = morris(planted, PLANTED, trajectories=20, levels=4, seed=0)
    assert r.inputs == ("a", "b", "c", "d")
    assert r.runs == 20 * (4 + 1) and r.trajectories == 20 and r.levels == 4
    assert r.ranked()[0] == "a" and r.ranked()[-1] == "c"
    assert r.mu_star[2] == pytest.approx(0.0, abs=1e-12) and r.sigma[2] == pytest.approx(0.0, abs=1e-12)
    assert r.mu_star[0] == pytest.approx(10.5, abs=0.6)  # 10 + the mean of d over the grid
    assert all(c >= 0 for c in r.mu_star_conf)
    lines = explain(r, "the toy")
    assert lines[0].startswith("a moves the toy by μ* = ")
    assert lines[-1] == "c barely moves the toy (μ* = 0): hold it at its nominal"


def test_morris_screens_the_whole_registry_through_its_space():
    unknowns = load_unknowns()
    space = InputSpace.from_unknowns(unknowns)

    def model(q):
        return np.array([math.log(v["led_intensity_red"]) for v in space.values(q)])

    r = morris(model, space, trajectories=4, seed=1)
    assert r.inputs == space.names and r.runs == 4 * (space.dim + 1)
    assert r.ranked()[0] == "led_intensity_red"
    assert sorted(r.mu_star)[-2] == 0.0  # nothing else moves it
    # an elementary effect on the log scale: the whole log range per unit of the cube
    i = space.names.index("led_intensity_red")
    assert r.mu_star[i] == pytest.approx(math.log(8.2 / 3.0), rel=1e-9)
    line = explain(r, "log Iv", unknowns=unknowns)[0]
    assert line.startswith("led_intensity_red (data.leds.red.luminous_intensity_cd) moves log Iv")


def test_same_seed_same_numbers_bitwise():
    m1, m2 = (morris(planted, PLANTED, trajectories=10, seed=7) for _ in range(2))
    assert m1 == m2
    assert np.array(m1.mu_star).tobytes() == np.array(m2.mu_star).tobytes()
    assert np.array(m1.mu_star_conf).tobytes() == np.array(m2.mu_star_conf).tobytes()
    s1, s2 = (sobol(ishigami, ISHIGAMI, n=256, seed=7) for _ in range(2))
    assert s1 == s2
    for field in ("s1", "s1_conf", "st", "st_conf"):
        assert np.array(getattr(s1, field)).tobytes() == np.array(getattr(s2, field)).tobytes()
    assert sobol(ishigami, ISHIGAMI, n=256, seed=8).s1 != s1.s1
    assert morris(planted, PLANTED, trajectories=10, seed=8).mu_star != m1.mu_star
    # seed 0 too (SALib's Sobol' bootstrap reads a seed of 0 as none: the engine never passes it one)
    assert sobol(ishigami, ISHIGAMI, n=64, seed=0) == sobol(ishigami, ISHIGAMI, n=64, seed=0)


LEVELS = {"low": 0.0, "mid": 1.0, "high": 3.0}
WITH_CHOICE = InputSpace((Input("x", 0.0, 1.0), Input("grade", choices=tuple(LEVELS)), Input("inert", 0.0, 1.0)))


def test_a_choice_input_is_sampled_in_equal_shares_and_gets_its_index():
    counts = {}

    def model(q):
        values = WITH_CHOICE.values(q)
        for v in values:
            counts[v["grade"]] = counts.get(v["grade"], 0) + 1
        return np.array([v["x"] + LEVELS[v["grade"]] for v in values])

    r = sobol(model, WITH_CHOICE, n=1024, seed=0)
    shares = np.array([counts[c] for c in LEVELS]) / sum(counts.values())
    np.testing.assert_allclose(shares, 1 / 3, atol=0.01)
    # x uniform (variance 1/12) plus a choice of {0, 1, 3} equally likely (variance 14/9): additive
    v_choice = np.var(list(LEVELS.values()))
    expected = np.array([1 / 12, v_choice, 0.0]) / (1 / 12 + v_choice)
    np.testing.assert_allclose(r.s1, expected, atol=0.03)
    np.testing.assert_allclose(r.st, expected, atol=0.03)
    assert r.s1[1] > 0.9 and r.ranked()[0] == "grade"
    m = morris(model, WITH_CHOICE, trajectories=10, seed=0)
    assert m.mu_star[1] > m.mu_star[0] > 0 and m.mu_star[2] == 0.0


def test_the_emulator_path_ranks_ishigami_and_reports_its_loo_error():
    design = sobol_points(256, ISHIGAMI.dim, seed=0)
    em = emulate(ISHIGAMI, design, ishigami(design), output="ishigami", n_restarts=1, seed=0)
    assert isinstance(em, EmulatedModel) and em.runs == 256
    assert len(em.loo.standardised_errors) == 256 and np.all(np.isfinite(em.loo.standardised_errors))
    assert em.loo.kind == "loo" and math.isfinite(em.loo.coverage_95) and math.isfinite(em.loo.rmse)
    assert 0 < em.relative_error < 0.5
    assert em(design[:5]).shape == (5,)
    r = sobol(em, ISHIGAMI, n=1024, seed=0)
    s1 = dict(zip(r.inputs, r.s1, strict=True))
    assert s1["x2"] >= s1["x1"] > s1["x3"]
    assert r.ranked("st")[0] == "x1"
    lines = explain(r, "the Ishigami function", emulated=em)
    assert lines[-1] == em.describe()
    assert lines[-1].startswith(f"on an emulator of 256 runs, LOO relative error {100 * em.relative_error:.1f} %")


def test_an_emulator_that_cannot_predict_its_left_out_runs_is_said_not_to_be_acted_on():
    """Eight runs of the Ishigami function (its sin² and x3⁴ sin terms need far more): the LOO error is
    most of the outputs' spread, and the ranking opens with the caution; 256 runs do not."""
    design = sobol_points(8, ISHIGAMI.dim, seed=0)
    em = emulate(ISHIGAMI, design, ishigami(design), output="ishigami", n_restarts=1, seed=0)
    assert em.relative_error > 0.5
    lines = explain(sobol(em, ISHIGAMI, n=256, seed=0), "the Ishigami function", emulated=em)
    assert lines[0].startswith(f"do not act on this ranking yet: the emulator misses the runs it leaves out by "
                               f"{100 * em.relative_error:.0f} % of their spread (8 runs of 3 inputs)")  # fmt: skip


def test_the_emulator_leaves_failed_runs_out():
    design = sobol_points(64, 3, seed=1)
    y = ishigami(design)
    y[[3, 10]] = np.nan
    em = emulate(ISHIGAMI, design, y, n_restarts=0)
    assert em.runs == 62


def test_explain_ranks_by_share_of_variance_in_words():
    space = InputSpace(
        (Input("led_intensity_red", 3.0, 8.2, log=True), Input("led_drive", 0.05, 20.0, log=True), Input("z", 0, 1))
    )
    r = sobol(lambda q: 3 * q[:, 0] + q[:, 1], space, n=512, seed=0)
    lines = explain(
        r,
        output="the far limit",
        unknowns=load_unknowns(),
        descriptions={"led_intensity_red": "the LED's luminous intensity bin"},
    )
    assert lines[0] == (
        "measure led_intensity_red (the LED's luminous intensity bin): it explains 90 % of the far limit's variance "
        "(total effect 90 %)"
    )
    assert lines[1].startswith("measure led_drive (scenario.led_current_mA): it explains 10 %")
    assert lines[2] == "hold z at its nominal: its total effect is 0 % of the far limit's variance"
    assert len(lines) == 3  # additive: no interaction sentence
    ish = explain(sobol(ishigami, ISHIGAMI, n=1024, seed=0), "the Ishigami function")
    assert ish[0].startswith("measure x2: it explains 44 %")
    assert ish[2].startswith(
        "x3 acts only with other inputs: it explains 0 % of the Ishigami function's variance alone"
    )
    assert ish[3].startswith("the indices do not sum to 1: interactions (Σ S1 = 76 %")
    held = explain(sobol(ishigami, ISHIGAMI, inputs=["x1", "x2"], n=64, seed=0))
    assert held[-1] == "over 2 of 3 inputs; x3 held at nominal"


def test_records_are_strict_json():
    for r in (sobol(ishigami, ISHIGAMI, n=64, seed=0, second_order=True), morris(planted, PLANTED, seed=0)):
        d = json.loads(json.dumps(r.to_json(), allow_nan=False))
        assert d["inputs"] == list(r.inputs) and d["method"] == ("sobol" if isinstance(r, Sobol) else "morris")
        assert d["runs"] == r.runs


def bad(call, message):
    with pytest.raises(ValueError, match=message) as e:
        call()
    assert "\n" not in str(e.value)


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (
            lambda: sobol(ishigami, ISHIGAMI, inputs=["x"]),
            r"^inputs: no unknown 'x' in the space \(expected some of x1",
        ),
        (lambda: sobol(ishigami, ISHIGAMI, inputs=[]), r"^inputs: expected at least one input name$"),
        (lambda: sobol(ishigami, ISHIGAMI, inputs="x1"), r"^inputs: expected a list of input names"),
        (lambda: sobol(ishigami, ISHIGAMI, inputs=["x1", "x1"]), r"^inputs: 'x1' named twice$"),
        (lambda: sobol(ishigami, ISHIGAMI, n=100), r"^n: expected a power of 2 >= 8, got 100$"),
        (lambda: sobol(ishigami, ISHIGAMI, n=4), r"^n: expected a power of 2 >= 8, got 4$"),
        (lambda: sobol(ishigami, ISHIGAMI, n=64.0), r"^n: expected a power of 2 >= 8"),
        (lambda: sobol(ishigami, ISHIGAMI, seed=-1), r"^seed: expected an integer >= 0, got -1$"),
        (lambda: sobol(ishigami, ISHIGAMI, second_order=1), r"^second_order: expected True or False"),
        (lambda: sobol(ishigami, ISHIGAMI, inputs=["x1"], nominal={"x2": 0}), r"^nominal: no value for 'x3'"),
        (lambda: sobol(ishigami, ISHIGAMI, inputs=["x1", "x2"], nominal={"x3": 9}), r"^nominal: x3=9 is outside \["),
        (lambda: sobol(ishigami, ISHIGAMI, inputs=["x1", "x2"], nominal=[1]), r"^nominal: expected a mapping"),
        (lambda: sobol(ishigami, [1, 2]), r"^space: expected an InputSpace, got list$"),
        (lambda: sobol(lambda q: q, ISHIGAMI, n=8), r"^model: expected outputs of shape \(40,\), got shape \(40, 3\)$"),
        (
            lambda: sobol(lambda q: np.where(np.arange(len(q)) == 3, np.nan, 1.0) + q[:, 1], ISHIGAMI, n=8),
            r"^model: 1 of 40 outputs are not finite",
        ),
        (lambda: sobol(lambda q: np.ones(len(q)), ISHIGAMI, n=8), r"^model: every output is 1.0; a constant output"),
        (lambda: sobol(None, ISHIGAMI, n=8), r"^model: expected a callable"),
        (lambda: morris(planted, PLANTED, trajectories=1), r"^trajectories: expected an integer >= 2, got 1$"),
        (lambda: morris(planted, PLANTED, levels=3), r"^levels: expected an even integer >= 2, got 3$"),
        (lambda: morris(planted, PLANTED, levels=True), r"^levels: expected an integer >= 2"),
        (lambda: morris(planted, PLANTED, seed="a"), r"^seed: expected an integer >= 0"),
        (lambda: emulate(ISHIGAMI, np.zeros((5, 2)), np.zeros(5)), r"^design: expected points of shape \(n, 3\)"),
        (lambda: emulate(ISHIGAMI, np.full((5, 3), 2.0), np.zeros(5)), r"^design: expected unit-cube points"),
        (lambda: emulate(ISHIGAMI, np.zeros((5, 3)), np.zeros(4)), r"^outputs: expected shape \(5,\)"),
        (lambda: explain({"s1": [1.0]}), r"^result: expected a Sobol or Morris record, got dict$"),
        (lambda: Sobol.ranked(sobol(ishigami, ISHIGAMI, n=8), by="s2"), r"^by: expected 's1' or 'st'"),
    ],
)
def test_bad_arguments_are_one_line_errors_naming_the_argument(call, message):
    bad(call, message)


def test_the_nominal_of_the_registry_holds_a_subset():
    unknowns = load_unknowns()
    space = InputSpace.from_unknowns(unknowns)

    def model(q):
        v = space.values(q)
        return np.array([math.log(p["led_intensity_red"]) + 0.1 * math.log(p["led_drive"]) for p in v])

    r = sobol(model, space, inputs=["led_intensity_red", "led_drive"], nominal=nominal(unknowns), n=64, seed=0)
    assert r.inputs == ("led_drive", "led_intensity_red") and len(r.held) == space.dim - 2
    values = nominal(unknowns)
    for inp, (name, q) in zip((i for i in space.inputs if i.name not in r.inputs), r.held, strict=True):
        assert inp.name == name and 0 <= q <= 1
        back = inp.from_unit([q])[0]  # the held coordinate is the registry's nominal, back through the space
        assert back == values[name] if inp.categorical else back == pytest.approx(values[name], rel=1e-9)
    assert r.ranked()[0] == "led_intensity_red"
    assert explain(r)[-1] == f"over 2 of {space.dim} inputs; the other {space.dim - 2} held at nominal"


def test_aliased_inputs_are_the_pairs_whose_choices_move_together_at_every_run():
    """On 16 scrambled Sobol' points of 31 two-choice inputs, the aliased pairs are exactly those whose
    indicator columns correlate ±1 (computed here directly); only 8 distinct splits exist."""
    space = InputSpace(tuple(Input(f"c{j}", choices=("a", "b")) for j in range(31)))
    design = sobol_points(16, space.dim, seed=0)
    groups = aliased_inputs(space, design)
    from_groups = {frozenset(p) for g in groups for p in itertools.combinations(g, 2)}
    r = np.corrcoef((design < 0.5).T.astype(float))
    direct = {
        frozenset((f"c{i}", f"c{j}")) for i, j in zip(*np.triu_indices(31, 1), strict=True) if abs(r[i, j]) > 0.999
    }
    assert from_groups == direct and len(direct) > 0
    singles = 31 - sum(len(g) for g in groups)
    assert len(groups) + singles == 8
    assert aliased_inputs(space, np.random.default_rng(0).random((64, 31))) == ()


def test_a_three_choice_input_aliases_only_with_the_same_split_and_a_constant_one_not_at_all():
    space = InputSpace(
        (
            Input("three", choices=("x", "y", "z")),
            Input("two", choices=("p", "q")),
            Input("relabelled", choices=("u", "v", "w")),
            Input("fixed_a", choices=("m", "n")),
            Input("fixed_b", choices=("m", "n")),
            Input("x", 0.0, 1.0),
        )
    )
    q = np.array(
        [
            [0.1, 0.2, 0.9, 0.1, 0.2, 0.5],
            [0.5, 0.7, 0.1, 0.2, 0.1, 0.5],
            [0.9, 0.7, 0.5, 0.3, 0.4, 0.5],
            [0.2, 0.1, 0.8, 0.4, 0.3, 0.5],
        ]
    )
    assert aliased_inputs(space, q) == (("three", "relabelled"),)


def test_the_explanation_says_when_the_runs_cannot_tell_two_ranked_inputs_apart():
    """A planted output driven by one of two aliased choices: the sentence names both; with a design that
    separates them, no such sentence."""
    space = InputSpace((Input("housing", choices=("white", "black")), Input("paper", choices=("matched", "white")),
                        Input("x", 0.0, 1.0)))  # fmt: skip
    rng = np.random.default_rng(3)
    u = rng.random((24, 3))
    aliased = u.copy()
    aliased[:, 1] = np.where(u[:, 0] < 0.5, 0.25, 0.75)

    def model(q):
        return 5.0 * (q[:, 0] >= 0.5) + 0.1 * q[:, 2]

    for design, expect in ((aliased, True), (u, False)):
        em = emulate(space, design, model(design), n_restarts=1, seed=0)
        lines = explain(sobol(em, space, n=256, seed=0), "the far limit", emulated=em)
        said = [line for line in lines if line.startswith("the 24 runs cannot tell housing and paper apart")]
        assert bool(said) is expect, lines
        assert em.aliases == ((("housing", "paper"),) if expect else ())
