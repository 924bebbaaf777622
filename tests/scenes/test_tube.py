"""The tube's floor plan against independent answers: its centreline is parameterised by arc length
with the heading of its tangent, its distance function is the brute-force distance to a densely
sampled centreline, a right turn is the mirror image of a left one, and a straight tube hides nothing."""

from __future__ import annotations

import doctest

import numpy as np
import pytest

from scenes import tube as tube_module
from scenes.tube import Tube

BENDS = [Tube(3.0, 90.0, 10.0, 5.0), Tube(3.0, -60.0, 4.0, 6.0), Tube(2.0, 150.0, 0.0, 1.5)]


@pytest.mark.parametrize("tube", BENDS)
def test_the_centreline_is_arc_length_parameterised_with_its_tangents_heading(tube):
    s = np.linspace(0.0, 40.0, 400_001)
    xy, heading = tube.centreline(s)
    steps = np.diff(xy, axis=0)
    np.testing.assert_allclose(np.hypot(*steps.T), np.diff(s), rtol=1e-6)  # unit speed
    tangent = np.arctan2(steps[:, 1], steps[:, 0])
    mid = 0.5 * (heading[1:] + heading[:-1])
    assert np.abs(np.angle(np.exp(1j * (tangent - mid)))).max() < 1e-4  # one step turns ≤ 7e-5 rad
    assert heading[-1] == pytest.approx(np.radians(tube.bend_deg))


@pytest.mark.parametrize("tube", BENDS)
def test_the_distance_is_the_brute_force_distance_to_the_centreline(tube):
    s = np.linspace(-60.0, 60.0, 240_001)  # 0.5 mm apart, the straights extended both ways
    line, _ = tube.centreline(np.clip(s, 0.0, None))
    line[s < 0] = np.column_stack([s[s < 0], np.zeros((s < 0).sum())])
    points = np.random.default_rng(1).uniform([-5.0, -15.0], [25.0, 25.0], (300, 2))
    brute = np.array([np.hypot(*(line - p).T).min() for p in points])
    assert tube.distance_from_centreline(points) == pytest.approx(brute, abs=1e-3)


def test_a_right_turn_is_the_mirror_of_a_left_one():
    left, right = Tube(3.0, 70.0, 5.0, 4.0), Tube(3.0, -70.0, 5.0, 4.0)
    s = np.linspace(0.0, 30.0, 301)
    (a, ha), (b, hb) = left.centreline(s), right.centreline(s)
    assert b == pytest.approx(a * [1.0, -1.0]) and hb == pytest.approx(-ha)
    p = np.random.default_rng(2).uniform(-10.0, 20.0, (200, 2))
    assert right.distance_from_centreline(p * [1.0, -1.0]) == pytest.approx(left.distance_from_centreline(p))
    assert right.clear((2.0, 0.5), (12.0, -8.0)) == left.clear((2.0, -0.5), (12.0, 8.0))


def test_a_straight_tube_hides_nothing_and_offsets_are_to_the_left():
    tube = Tube(3.0)
    xy, heading = tube.at([0.0, 7.5], [1.0, -0.5])
    assert xy.tolist() == [[0.0, 1.0], [7.5, -0.5]] and heading.tolist() == [0.0, 0.0]
    assert tube.distance_from_centreline([[4.0, -1.25]]) == pytest.approx([1.25])
    assert tube.clear((0.0, -1.4), (100.0, 1.4))


def test_the_module_example_holds():
    assert doctest.testmod(tube_module).failed == 0


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"width_m": 0.0}, "tube_width_m: expected a width > 0 m"),
        ({"bend_deg": 180.0}, r"bend_deg: expected a turn in \(-180, 180\)"),
        ({"bend_at_m": -1.0}, "bend_at_m: expected a distance >= 0 m"),
        (
            {"bend_deg": 30.0, "bend_radius_m": 1.5},
            r"bend_radius_m: expected a radius > half the tube's width \(1.5 m\)",
        ),
    ],
)
def test_bad_input_is_one_line(fields, message):
    with pytest.raises(ValueError, match=f"^{message}"):
        Tube(**fields).validate()
