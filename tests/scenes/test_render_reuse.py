"""Kernel reuse across geometries: the crop-independent render gives mitsuba.render's pixels."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from scenes.render import render_unit_groups
from scenes.shapes import disk_shape, rect_shape

pytestmark = pytest.mark.usefixtures("mitsuba_variant")


def _spec(camera_x: float, crop: list[int]) -> dict:
    """A lit disc (group ``led:a``) over a floor lit by a ceiling panel (``ambient``), seen
    from ``camera_x`` m along -x on a 64 × 48 film; the structure does not depend on the
    arguments, only the camera pose and the crop (x0, y0, width, height) do."""
    face = {"type": "marker_face", "group": "led:a", "radiance": 2.5, "exponent": 3.0}
    ceiling = {"type": "area", "group": "ambient", "radiance": 1.0}
    return {
        "sensor": {
            "position": [camera_x, 0.0, 0.0],
            "target": [camera_x + 1.0, 0.0, 0.0],
            "up": [0.0, 0.0, -1.0],
            "fov_x_deg": 40.0,
            "film": [64, 48],
            "crop": crop,
        },
        "materials": {"grey": 0.5, "white": 0.8},
        "shapes": [
            disk_shape(np.array([1.0, 0.0, 0.0]), np.array([-1.0, 0.2, 0.1]), 0.2, "white", face),
            rect_shape(np.array([1.0, 0.0, 0.3]), [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], 2.0, 2.0, "grey"),
            rect_shape(np.array([1.0, 0.0, -0.6]), [0.0, 1.0, 0.0], [1.0, 0.0, 0.0], 2.0, 2.0, "grey", ceiling),
        ],
        "max_depth": 4,
    }


# geometries whose blocks (width × height × 4 channels) need the same power-of-two buffer
GEOMETRIES = [(-0.5, [8, 4, 40, 30]), (-0.8, [20, 10, 36, 30])]
MORE_GEOMETRIES = [(-0.6, [10, 6, 38, 30]), (-0.7, [14, 8, 36, 31]), (-0.9, [4, 12, 40, 29]), (-0.55, [16, 2, 37, 30])]


@pytest.fixture
def one_thread():
    """Run Dr.Jit's LLVM backend on one thread for the test.

    The backend hands a kernel's work to its threads at run time, and the image block's
    sums can depend on how the work fell: with spp 3 on a 36 × 31 crop, while two busy
    loops shared the two cores, 7 of 40 ``mitsuba.render`` renders and 6 of 40 reuse-path
    renders differed from the rest in a pixel's last bit (on one thread: one result in 60
    renders of each path); spp 4, 16 and 1024 gave one result in 40. Same pixels are only defined
    for the same summation order, so the comparison runs on one thread."""
    import drjit as dr

    threads = dr.thread_count()
    dr.set_thread_count(1)
    try:
        yield
    finally:
        dr.set_thread_count(threads)


def _render_kernel_hash(history: list[dict]) -> str:
    """Hash of the largest kernel of a kernel history (the path tracer's)."""
    return max((k for k in history if "operation_count" in k), key=lambda k: k["operation_count"])["hash"]


@pytest.mark.usefixtures("one_thread")
@pytest.mark.parametrize("spp", [4, 3])
def test_reused_kernel_renders_the_same_pixels_as_mitsuba_render(spp):
    """Same pixels as ``mitsuba.render`` for six geometries (camera pose and crop), with
    fewer distinct render kernels: ``mitsuba.render`` bakes each crop into its kernel.

    Dr.Jit now and then orders a loop's state variables differently for the same program
    (measured: about 1 render in 10 gets one of a few permuted kernels, each compiled once,
    then found in its disk cache), so the test counts distinct kernels rather than
    requiring a single one."""
    import drjit as dr

    hashes: dict[bool, set[str]] = {True: set(), False: set()}
    for camera_x, crop in GEOMETRIES + MORE_GEOMETRIES:
        spec = _spec(camera_x, crop)
        images = {}
        for reuse in (True, False):
            dr.kernel_history()  # clear
            dr.set_flag(dr.JitFlag.KernelHistory, True)
            try:
                images[reuse] = render_unit_groups(spec, spp, 5, reuse_kernels=reuse)
                hashes[reuse].add(_render_kernel_hash(dr.kernel_history()))
            finally:
                dr.set_flag(dr.JitFlag.KernelHistory, False)
        assert sorted(images[True]) == sorted(images[False]) == ["ambient", "led:a"]
        for group, image in images[False].items():
            assert image.shape == (crop[3], crop[2])
            assert image.max() > 0, group
            np.testing.assert_array_equal(images[True][group], image, err_msg=f"{group}, crop {crop}")
    n = len(GEOMETRIES + MORE_GEOMETRIES)
    assert len(hashes[False]) == n, "mitsuba.render was expected to compile a kernel per crop"
    # a kernel that depended on the crop would give n; permuted orderings alone rarely give more than 2
    assert len(hashes[True]) < n, f"the reuse path compiled {len(hashes[True])} kernels for {n} geometries"


@pytest.mark.usefixtures("one_thread")
def test_reused_kernel_on_a_beacon_scene_at_two_ranges():
    from scenes.assemble import scene_spec
    from scenes.scenario import RenderSettings, Scenario

    settings = RenderSettings(spp=4, oversampling=1, crop="target", near_field_spp=16)
    for range_m in (9.0, 11.0):
        spec = scene_spec(Scenario(range_m=range_m, render=settings))
        reused = render_unit_groups(spec, 4, 7, ["led:red"])["led:red"]
        fresh = render_unit_groups(spec, 4, 7, ["led:red"], reuse_kernels=False)["led:red"]
        assert reused.max() > 0
        np.testing.assert_array_equal(reused, fresh, err_msg=f"range {range_m} m")


SCALAR_CODE = (
    "import json, numpy as np, sys; sys.path.insert(0, 'tests/scenes');"
    "from scenes.mitsuba_variant import select_variant; v = select_variant('mono').variant;"
    "from test_render_reuse import GEOMETRIES, _spec; from scenes.render import render_unit_groups;"
    "spec = _spec(*GEOMETRIES[0]);"
    "a = render_unit_groups(spec, 2, 5); b = render_unit_groups(spec, 2, 5, reuse_kernels=False);"
    "print(json.dumps([v, {g: [a[g].shape, bool(np.array_equal(a[g], b[g])), float(a[g].max())] for g in a}]))"
)


def test_scalar_fallback_ignores_kernel_reuse():
    """The scalar variant renders one scene per group, as before, whatever ``reuse_kernels`` says."""
    env = {**os.environ, "BEACON_SIM_VARIANT": "scalar"}
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    proc = subprocess.run(
        [sys.executable, "-c", SCALAR_CODE], capture_output=True, text=True, env=env, cwd=root, timeout=300
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    variant, groups = json.loads(proc.stdout.strip().splitlines()[-1])
    assert variant == "scalar_rgb"
    assert sorted(groups) == ["ambient", "led:a"]
    for group, (shape, same, peak) in groups.items():
        assert shape == [30, 40] and same and peak > 0, group
