"""``diffuse_sheet``: a thin diffusing sheet (paper).

Reflects a fraction R and transmits a fraction T of incident light, each as a perfect
Lambertian lobe, on both sides: f = R/π on the incident side, T/π on the other.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

__all__ = ["diffuse_sheet_class"]


def diffuse_sheet_class():
    """Build the sheet BSDF class against the active variant's ``mi.BSDF``."""

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
