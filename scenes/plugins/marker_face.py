"""``marker_face``: an area emitter with a cosine-power or tabulated angular pattern.

Mitsuba's ``area`` emitter is Lambertian: constant radiance in every direction. A bare
LED is far from that; its radiant intensity falls as I(θ) = I₀ cosᵐθ about its axis
(``m ≈ 20`` for a 30° lamp). Spread over a flat lit face of area A whose normal is the
LED axis, that intensity is the radiance

    L(θ) = I(θ) / (A cos θ) = (I₀ / A) cos^(m−1) θ,

which is what the ``marker_face`` plugin emits: ``radiance`` × cos^``exponent`` θ with
``exponent = m − 1`` (``exponent = 0`` is Lambertian). An LED with a Lambertian wide
component s (:mod:`scenes.led`) adds ``wide`` = s: ``radiance`` × [(1 − s) cos^``exponent`` θ + s].
Direct sampling picks points uniformly on the shape, as Mitsuba's own area emitter does; the returned weights and
pdfs are consistent, so multiple importance sampling stays unbiased.

A marker with diffusers instead carries a ``profile``: a bitmap texture holding its
exit radiance L(r, θ) (rows: viewing angle θ from 0 to 90°, columns: radius r from the
centre to the edge, values at bin centres), which multiplies ``radiance``.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

__all__ = ["marker_face_class"]


def marker_face_class():
    """Build the emitter class against the active variant's ``mi.Emitter``."""

    class MarkerFace(mi.Emitter):
        """Area emitter with radiance L(θ) = radiance · cos^exponent θ (one-sided)."""

        def __init__(self, props: mi.Properties) -> None:
            mi.Emitter.__init__(self, props)
            self.radiance = dr.opaque(mi.Float, props.get("radiance", 1.0))
            self.exponent = float(props.get("exponent", 0.0))
            self.wide = float(props.get("wide", 0.0))  # Lambertian share s of the on-axis radiance
            self.profile = props.get("profile", None)  # texture over (r, θ), or None
            if self.exponent < 0:
                raise ValueError("marker_face.exponent: expected >= 0")
            if not 0.0 <= self.wide <= 1.0:
                raise ValueError("marker_face.wide: expected 0 <= wide <= 1")
            self.m_flags = mi.EmitterFlags.Surface
            # a per-shape tag that keeps the scene parser from merging identical faces
            self.instance = int(props.get("instance", 0))

        def _emitted(self, cos_theta, uv):
            lobe = dr.power(dr.maximum(cos_theta, 0.0), self.exponent)
            if self.wide > 0.0:
                lobe = (1.0 - self.wide) * lobe + self.wide
            if self.profile is not None:
                lookup = dr.zeros(mi.SurfaceInteraction3f)
                theta = dr.acos(dr.clip(cos_theta, 0.0, 1.0))
                # disk uv = (r / radius, φ / 2π); the table's u is r, its v is θ / 90°
                lookup.uv = mi.Point2f(uv.x, theta * (2.0 / dr.pi))
                lobe = lobe * self.profile.eval_1(lookup)
            return dr.select(cos_theta > 0.0, self.radiance * lobe, 0.0)

        def eval(self, si, active=True):
            return mi.Spectrum(self._emitted(mi.Frame3f.cos_theta(si.wi), si.uv))

        def sample_direction(self, it, sample, active=True):
            ds = self.get_shape().sample_direction(it, sample, active)
            cos_theta = dr.dot(ds.n, -ds.d)
            ok = active & (cos_theta > 0.0) & (ds.pdf > 0.0)
            ds.pdf = dr.select(ok, ds.pdf, 0.0)
            ds.emitter = mi.EmitterPtr(self) if hasattr(mi, "EmitterPtr") else self  # scalar: plain pointer
            weight = dr.select(ok, self._emitted(cos_theta, ds.uv) / dr.maximum(ds.pdf, 1e-30), 0.0)
            return ds, mi.Spectrum(weight)

        def pdf_direction(self, it, ds, active=True):
            cos_theta = dr.dot(ds.n, -ds.d)
            pdf = self.get_shape().pdf_direction(it, ds, active)
            return dr.select(active & (cos_theta > 0.0), pdf, 0.0)

        def eval_direction(self, it, ds, active=True):
            return mi.Spectrum(self._emitted(dr.dot(ds.n, -ds.d), ds.uv))

        def sample_wavelengths(self, si, sample, active=True):
            return mi.Wavelength(0.0), mi.Spectrum(1.0)

        def traverse(self, callback):
            callback.put("radiance", self.radiance, mi.ParamFlags.NonDifferentiable)

        def parameters_changed(self, keys):
            pass

        def to_string(self):
            return f"MarkerFace[exponent={self.exponent}]"

    return MarkerFace
