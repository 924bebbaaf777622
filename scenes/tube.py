"""A lava tube seen from above: its centreline (straight, or with one circular bend) and its walls.

The tube is the set of points within ``width_m / 2`` of its centreline (the floor plan of a tube of
constant width). The centreline runs along +x from the origin, turns by ``bend_deg`` (positive to
the left, counter-clockwise seen from above) on a circular arc of radius ``bend_radius_m`` that
starts ``bend_at_m`` along it, and runs straight on. Positions along it are arc lengths s (m);
``lateral`` offsets are to the left of the direction of travel (m). A sight line is clear when it
stays inside the tube (:meth:`Tube.clear`): the inner wall of a bend hides what lies around it.

Example
-------
>>> tube = Tube(width_m=3.0, bend_deg=90.0, bend_at_m=10.0, bend_radius_m=5.0)
>>> xy, heading = tube.centreline([20.0])
>>> [round(float(v), 6) for v in (*xy[0], heading[0])]
[15.0, 7.146018, 1.570796]
>>> tube.clear((5.0, 0.0), (11.5, 1.3)), tube.clear((5.0, 0.0), (15.0, 5.1))
(True, False)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["Tube"]


@dataclass(frozen=True)
class Tube:
    """A tube's floor plan (lengths in m, angles in degrees; module docstring).

    Attributes
    ----------
    width_m
        Wall to wall.
    bend_deg
        The centreline's turn, degrees in (−180, 180); positive to the left; 0: straight.
    bend_at_m
        Arc length at which the bend starts.
    bend_radius_m
        Radius of the centreline's arc (> ``width_m / 2``, so the inner wall is a curve, not a cusp).
    """

    width_m: float = 3.0
    bend_deg: float = 0.0
    bend_at_m: float = 20.0
    bend_radius_m: float = 6.0

    def validate(self) -> None:
        """One-line errors naming the field."""
        if not self.width_m > 0:
            raise ValueError(f"tube_width_m: expected a width > 0 m, got {self.width_m!r}")
        if not (math.isfinite(self.bend_deg) and abs(self.bend_deg) < 180):
            raise ValueError(f"bend_deg: expected a turn in (-180, 180) degrees, got {self.bend_deg!r}")
        if not (math.isfinite(self.bend_at_m) and self.bend_at_m >= 0):
            raise ValueError(f"bend_at_m: expected a distance >= 0 m along the tube, got {self.bend_at_m!r}")
        if not self.bend_radius_m > self.width_m / 2:
            raise ValueError(
                f"bend_radius_m: expected a radius > half the tube's width ({self.width_m / 2:g} m), "
                f"got {self.bend_radius_m!r}"
            )

    @property
    def _turn_rad(self) -> float:
        return math.radians(self.bend_deg)

    @property
    def bend_length_m(self) -> float:
        """Arc length of the bend, m."""
        return abs(self._turn_rad) * self.bend_radius_m

    def centreline(self, s_m: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Points (n × 2, m) and headings (n, rad, counter-clockwise from +x) at arc lengths ``s_m``."""
        s = np.asarray(s_m, dtype=np.float64).reshape(-1)
        s0, turn, r = self.bend_at_m, self._turn_rad, self.bend_radius_m
        if turn == 0:
            return np.column_stack([s, np.zeros_like(s)]), np.zeros_like(s)
        sign = math.copysign(1.0, turn)
        into = np.clip(s - s0, 0.0, self.bend_length_m)  # arc length travelled on the bend
        heading = sign * into / r
        x = np.minimum(s, s0) + r * np.sin(np.abs(heading))
        y = sign * r * (1 - np.cos(heading))
        beyond = np.maximum(s - s0 - self.bend_length_m, 0.0)  # straight on after the bend
        return np.column_stack([x + beyond * np.cos(heading), y + beyond * np.sin(heading)]), heading

    def at(self, s_m: ArrayLike, lateral_m: ArrayLike = 0.0) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Points ``lateral_m`` to the left of the centreline at arc lengths ``s_m`` (n × 2, m), and
        the centreline's headings there (rad)."""
        xy, heading = self.centreline(s_m)
        left = np.column_stack([-np.sin(heading), np.cos(heading)])
        return xy + np.asarray(lateral_m, dtype=np.float64).reshape(-1, 1) * left, heading

    def distance_from_centreline(self, points: ArrayLike) -> NDArray[np.float64]:
        """Distance of each point (n × 2, m) from the centreline (the straights extend for ever), m."""
        p = np.atleast_2d(np.asarray(points, dtype=np.float64))
        s0, turn = self.bend_at_m, self._turn_rad
        before = np.hypot(np.maximum(p[:, 0] - s0, 0.0), p[:, 1])  # the half-line x ≤ s0, y = 0
        if turn == 0:
            return np.abs(p[:, 1])
        (end,), (h_end,) = self.centreline([s0 + self.bend_length_m])
        d = np.array([math.cos(h_end), math.sin(h_end)])
        along = (p - end) @ d
        after = np.hypot(*(p - end - np.maximum(along, 0.0)[:, None] * d).T)  # the half-line beyond the bend
        sign = math.copysign(1.0, turn)
        centre = np.array([s0, sign * self.bend_radius_m])
        rel = p - centre
        # angle swept from the bend's start (the radius pointing from the centre to (s0, 0)), in the turn's sense
        swept = np.mod(sign * (np.arctan2(rel[:, 1], rel[:, 0]) - math.atan2(-sign, 0.0)), 2 * math.pi)
        on_arc = np.where(swept <= abs(turn), np.abs(np.hypot(*rel.T) - self.bend_radius_m), np.inf)
        return np.minimum(np.minimum(before, after), on_arc)

    def inside(self, points: ArrayLike) -> NDArray[np.bool_]:
        """Whether each point (n × 2, m) lies inside the walls."""
        return self.distance_from_centreline(points) <= self.width_m / 2

    def clear(self, a: ArrayLike, b: ArrayLike, step_m: float = 0.05) -> bool:
        """Whether the sight line from ``a`` to ``b`` (m) stays inside the walls (tested every
        ``step_m``); a straight tube hides nothing (both ends are taken to be inside it)."""
        if self.bend_deg == 0:
            return True
        a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
        n = max(2, math.ceil(np.hypot(*(b - a)) / step_m) + 1)
        return bool(self.inside(a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)).all())
