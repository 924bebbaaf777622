"""The project's Mitsuba plugins: the LED/marker-face emitter and the paper-sheet BSDF.

``marker_face`` — an area emitter with a cosine-power or tabulated angular pattern
--------------------------------------------------------------------------------

Mitsuba's ``area`` emitter is Lambertian: constant radiance in every direction. A bare
LED is far from that; its radiant intensity falls as I(θ) = I₀ cosᵐθ about its axis
(``m ≈ 20`` for a 30° lamp). Spread over a flat lit face of area A whose normal is the
LED axis, that intensity is the radiance

    L(θ) = I(θ) / (A cos θ) = (I₀ / A) cos^(m−1) θ,

which is what the ``marker_face`` plugin emits: ``radiance`` × cos^``exponent`` θ with
``exponent = m − 1`` (``exponent = 0`` is Lambertian). Direct sampling picks points
uniformly on the shape, as Mitsuba's own area emitter does; the returned weights and
pdfs are consistent, so multiple importance sampling stays unbiased.

A marker with diffusers instead carries a ``profile``: a bitmap texture holding its
exit radiance L(r, θ) (rows: viewing angle θ from 0 to 90°, columns: radius r from the
centre to the edge, values at bin centres), which multiplies ``radiance``.

``diffuse_sheet`` — a thin diffusing sheet (paper)
-------------------------------------------------
Reflects a fraction R and transmits a fraction T of incident light, each as a perfect
Lambertian lobe, on both sides: f = R/π on the incident side, T/π on the other.

Both are written in Python; Dr.Jit traces them into the same compiled kernels as the
C++ plugins in the LLVM and CUDA variants. They support the mono and RGB variants
(grey), which is all the project renders with.
"""

from __future__ import annotations

_REGISTERED: set[str] = set()


def register_plugins() -> None:
    """Register the project's plugins with the active Mitsuba variant (idempotent)."""
    import mitsuba as mi

    variant = mi.variant()
    if variant in _REGISTERED:
        return
    face, sheet = _marker_face_class(), _diffuse_sheet_class()
    mi.register_emitter("marker_face", lambda props: face(props))
    mi.register_bsdf("diffuse_sheet", lambda props: sheet(props))
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
            self.profile = props.get("profile", None)  # texture over (r, θ), or None
            if self.exponent < 0:
                raise ValueError("marker_face.exponent: expected >= 0")
            self.m_flags = mi.EmitterFlags.Surface
            # a per-shape tag that keeps the scene parser from merging identical faces
            self.instance = int(props.get("instance", 0))

        def _emitted(self, cos_theta, uv):
            lobe = dr.power(dr.maximum(cos_theta, 0.0), self.exponent)
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


def _diffuse_sheet_class():
    """Build the sheet BSDF class against the active variant's ``mi.BSDF``."""
    import drjit as dr
    import mitsuba as mi

    class DiffuseSheet(mi.BSDF):
        """Lambertian reflection R and Lambertian transmission T, on both sides."""

        def __init__(self, props: mi.Properties) -> None:
            mi.BSDF.__init__(self, props)
            self.r = float(props.get("reflectance", 0.5))
            self.t = float(props.get("transmittance", 0.5))
            if self.r < 0 or self.t < 0 or self.r + self.t > 1.0 + 1e-9:
                raise ValueError("diffuse_sheet: expected reflectance, transmittance >= 0 with sum <= 1")
            total = self.r + self.t
            self.p_reflect = self.r / total if total > 0 else 0.5
            flags = (
                mi.BSDFFlags.DiffuseReflection
                | mi.BSDFFlags.DiffuseTransmission
                | mi.BSDFFlags.FrontSide
                | mi.BSDFFlags.BackSide
            )
            self.m_components = [flags]
            self.m_flags = flags

        def sample(self, ctx, si, sample1, sample2, active=True):
            cos_i = mi.Frame3f.cos_theta(si.wi)
            reflect = sample1 < self.p_reflect
            wo = mi.warp.square_to_cosine_hemisphere(sample2)
            # reflected light stays on the side of wi, transmitted light goes to the other
            same_side = dr.select(cos_i >= 0.0, 1.0, -1.0)
            wo.z = dr.select(reflect, same_side, -same_side) * wo.z
            bs = dr.zeros(mi.BSDFSample3f)
            bs.wo = wo
            p_lobe = dr.select(reflect, self.p_reflect, 1.0 - self.p_reflect)
            bs.pdf = p_lobe * dr.abs(wo.z) / dr.pi
            bs.eta = 1.0
            bs.sampled_component = 0
            bs.sampled_type = mi.UInt32(
                dr.select(reflect, int(mi.BSDFFlags.DiffuseReflection), int(mi.BSDFFlags.DiffuseTransmission))
            )
            weight = dr.select(reflect, self.r, self.t) / p_lobe
            ok = active & (p_lobe > 0.0)
            bs.pdf = dr.select(ok, bs.pdf, 0.0)
            return bs, mi.Spectrum(dr.select(ok, weight, 0.0))

        def eval(self, ctx, si, wo, active=True):
            same = mi.Frame3f.cos_theta(si.wi) * mi.Frame3f.cos_theta(wo) > 0.0
            value = dr.select(same, self.r, self.t) * dr.abs(mi.Frame3f.cos_theta(wo)) / dr.pi
            return mi.Spectrum(dr.select(active, value, 0.0))

        def pdf(self, ctx, si, wo, active=True):
            same = mi.Frame3f.cos_theta(si.wi) * mi.Frame3f.cos_theta(wo) > 0.0
            p_lobe = dr.select(same, self.p_reflect, 1.0 - self.p_reflect)
            return dr.select(active, p_lobe * dr.abs(mi.Frame3f.cos_theta(wo)) / dr.pi, 0.0)

        def eval_pdf(self, ctx, si, wo, active=True):
            return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

        def traverse(self, callback):
            pass

        def to_string(self):
            return f"DiffuseSheet[R={self.r}, T={self.t}]"

    return DiffuseSheet
