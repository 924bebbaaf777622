"""A Mitsuba area emitter with a cosine-power angular pattern (the LED's lit face).

Mitsuba's ``area`` emitter is Lambertian: constant radiance in every direction. A bare
LED is far from that; its radiant intensity falls as I(θ) = I₀ cosᵐθ about its axis
(``m ≈ 20`` for a 30° lamp). Spread over a flat lit face of area A whose normal is the
LED axis, that intensity is the radiance

    L(θ) = I(θ) / (A cos θ) = (I₀ / A) cos^(m−1) θ,

which is what the ``marker_face`` plugin emits: ``radiance`` × cos^``exponent`` θ with
``exponent = m − 1`` (``exponent = 0`` is Lambertian). Direct sampling picks points
uniformly on the shape, as Mitsuba's own area emitter does; the returned weights and
pdfs are consistent, so multiple importance sampling stays unbiased.

The plugin is written in Python; Dr.Jit traces it into the same compiled kernels as the
C++ plugins in the LLVM and CUDA variants. It supports the mono and RGB variants (grey
emission), which is all the beacon-scale renders use.
"""

from __future__ import annotations

_REGISTERED: set[str] = set()


def register_plugins() -> None:
    """Register the project's plugins with the active Mitsuba variant (idempotent)."""
    import mitsuba as mi

    variant = mi.variant()
    if variant in _REGISTERED:
        return
    cls = _marker_face_class()
    mi.register_emitter("marker_face", lambda props: cls(props))
    _REGISTERED.add(variant)


def _marker_face_class():
    """Build the emitter class against the active variant's ``mi.Emitter``."""
    import drjit as dr
    import mitsuba as mi

    class MarkerFace(mi.Emitter):
        """Area emitter with radiance L(θ) = radiance · cos^exponent θ (one-sided)."""

        def __init__(self, props: mi.Properties) -> None:
            mi.Emitter.__init__(self, props)
            self.radiance = dr.opaque(mi.Float, props.get("radiance", 1.0))
            self.exponent = float(props.get("exponent", 0.0))
            if self.exponent < 0:
                raise ValueError("marker_face.exponent: expected >= 0")
            self.m_flags = mi.EmitterFlags.Surface
            # a per-shape tag that keeps the scene parser from merging identical faces
            self.instance = int(props.get("instance", 0))

        def _emitted(self, cos_theta):
            lobe = dr.power(dr.maximum(cos_theta, 0.0), self.exponent)
            return dr.select(cos_theta > 0.0, self.radiance * lobe, 0.0)

        def eval(self, si, active=True):
            return mi.Spectrum(self._emitted(mi.Frame3f.cos_theta(si.wi)))

        def sample_direction(self, it, sample, active=True):
            ds = self.get_shape().sample_direction(it, sample, active)
            cos_theta = dr.dot(ds.n, -ds.d)
            ok = active & (cos_theta > 0.0) & (ds.pdf > 0.0)
            ds.pdf = dr.select(ok, ds.pdf, 0.0)
            ds.emitter = mi.EmitterPtr(self)
            weight = dr.select(ok, self._emitted(cos_theta) / ds.pdf, 0.0)
            return ds, mi.Spectrum(weight)

        def pdf_direction(self, it, ds, active=True):
            cos_theta = dr.dot(ds.n, -ds.d)
            pdf = self.get_shape().pdf_direction(it, ds, active)
            return dr.select(active & (cos_theta > 0.0), pdf, 0.0)

        def eval_direction(self, it, ds, active=True):
            return mi.Spectrum(self._emitted(dr.dot(ds.n, -ds.d)))

        def sample_wavelengths(self, si, sample, active=True):
            return mi.Wavelength(0.0), mi.Spectrum(1.0)

        def traverse(self, callback):
            callback.put("radiance", self.radiance, mi.ParamFlags.NonDifferentiable)

        def parameters_changed(self, keys):
            pass

        def to_string(self):
            return f"MarkerFace[exponent={self.exponent}]"

    return MarkerFace
