"""A test scene: flat sheets under a uniform diffuse sky of unit radiance, seen from below.

A black Lambertian emitter just above the sheets gives uniform diffuse illumination and no
return reflection; a small perspective camera under them looks up, so the mean pixel is the
diffuse transmittance of the stack (radiance 1 in, T out).
"""

from __future__ import annotations

import numpy as np


def transmitted_radiance(sheet_bsdfs: list[dict], *, spp: int, max_depth: int, seed: int, gap_m: float = 1e-4) -> float:
    """Mean radiance under ``sheet_bsdfs`` (first at z = 0, then ``gap_m`` apart) lit from above."""
    import mitsuba as mi

    t, big = mi.ScalarTransform4f, 50.0
    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": max_depth, "rr_depth": max_depth},
        "sensor": {
            "type": "perspective",
            "fov": 20,
            "near_clip": 1e-4,
            "to_world": t().look_at([0, 0, -0.01], [0, 0, 1], [0, 1, 0]),
            "film": {
                "type": "hdrfilm",
                "width": 16,
                "height": 16,
                "pixel_format": "luminance",
                "rfilter": {"type": "box"},
            },
            "sampler": {"type": "independent", "sample_count": spp},
        },
        "light": {
            "type": "rectangle",
            "to_world": t().translate([0, 0, gap_m * (len(sheet_bsdfs) + 1)]).rotate([1, 0, 0], 180).scale(big),
            "emitter": {"type": "area", "radiance": 1.0},
            "bsdf": {"type": "diffuse", "reflectance": 0.0},
        },
    }
    for k, bsdf in enumerate(sheet_bsdfs):
        scene[f"sheet{k}"] = {
            "type": "rectangle",
            "to_world": t().translate([0, 0, gap_m * k]).scale(big),
            "bsdf": bsdf,
        }
    return float(np.asarray(mi.render(mi.load_dict(scene), seed=seed)).mean())
