"""The scalar fallback renders the same radiance as the fast variant (in its own process)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np

CODE = (
    "import json, numpy as np; from scenes.render import render; from scenes.scenario import Scenario, RenderSettings;"
    "from scenes.mitsuba_variant import select_variant; v = select_variant().variant;"
    "s = Scenario(range_m=9.0, render=RenderSettings(spp=16, oversampling=1, crop='target', near_field_spp=16));"
    "r = render(s, groups=['led:red']);"
    "img = r.component('led:red').image_W_m2_sr; print(json.dumps([v, float(img.sum()), float(img.max())]))"
)


def _run(variant: str | None):
    env = dict(os.environ)
    env.pop("BEACON_SIM_VARIANT", None)
    if variant:
        env["BEACON_SIM_VARIANT"] = variant
    proc = subprocess.run([sys.executable, "-c", CODE], capture_output=True, text=True, env=env, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_scalar_variant_renders_the_same_marker_radiance():
    fast_variant, fast_sum, fast_max = _run(None)
    scalar_variant, scalar_sum, scalar_max = _run("scalar")
    assert scalar_variant == "scalar_rgb"
    # direct view of the lit faces dominates: same peak radiance, total within sampling noise
    assert np.isclose(scalar_max, fast_max, rtol=1e-4)
    assert np.isclose(scalar_sum, fast_sum, rtol=0.03), (fast_variant, fast_sum, scalar_sum)
