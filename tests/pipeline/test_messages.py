"""The study's three messages: typed fields, JSON round trip, one-line errors naming the field."""

from __future__ import annotations

import math

import pytest

from pipeline.messages import BotPositionQuat, GlobalPos, LEDPoints


def _examples():
    s = math.sqrt(0.5)
    return [
        LEDPoints(3, "green", (0.0, -0.01, 0.012, 0.001, 0.0015), (0.0, 0.0, 0.0, -0.014, 0.014)),
        BotPositionQuat(4.25, (0.0, 0.0, s, s), (-1.0, 0.0, 0.0)),
        GlobalPos(-2.1, 0.35, -0.01, 0.17, -0.002, 0.001),
    ]


@pytest.mark.parametrize("msg", _examples(), ids=lambda m: type(m).__name__)
def test_json_round_trip_is_exact(msg):
    again = type(msg).from_json(msg.to_json())
    assert again == msg
    assert again.to_json() == msg.to_json()


@pytest.mark.parametrize(
    ("make", "field"),
    [
        (lambda: LEDPoints(-1, "red", (0,) * 5, (0,) * 5), "camera"),
        (lambda: LEDPoints(0, "purple", (0,) * 5, (0,) * 5), "colour"),
        (lambda: LEDPoints(0, "red", (0,) * 4, (0,) * 5), "azimuth_rad"),
        (lambda: LEDPoints(0, "red", (0,) * 5, (0, 0, 0, 0, float("nan"))), "elevation_rad[4]"),
        (lambda: BotPositionQuat(0.0, (0, 0, 0, 1), (1, 0, 0)), "range_m"),
        (lambda: BotPositionQuat(1.0, (0, 0, 0, 2), (1, 0, 0)), "quaternion_xyzw"),
        (lambda: BotPositionQuat(1.0, (0, 0, 0, 1), (1, 1, 0)), "r1"),
        (lambda: GlobalPos(0, 0, "x", 0, 0, 0), "z_m"),
    ],
)
def test_bad_fields_give_one_line_errors_naming_the_field(make, field):
    with pytest.raises(ValueError) as exc:
        make()
    msg = str(exc.value)
    assert msg.startswith(f"{field}:") and "\n" not in msg


def test_unknown_and_missing_json_fields_are_named():
    with pytest.raises(ValueError, match=r"^extra: unknown field"):
        GlobalPos.from_json('{"x_m":0,"y_m":0,"z_m":0,"yaw_rad":0,"pitch_rad":0,"roll_rad":0,"extra":1}')
    with pytest.raises(ValueError, match=r"^roll_rad: missing field"):
        GlobalPos.from_json('{"x_m":0,"y_m":0,"z_m":0,"yaw_rad":0,"pitch_rad":0}')
    with pytest.raises(ValueError, match=r"^LEDPoints: not valid JSON"):
        LEDPoints.from_json("{")
