"""Commands that list the hardware: ``beacons`` and ``cameras`` (a table, or ``--json``)."""

from __future__ import annotations

import json

from camera_models.camera import load_camera
from scenes.beacon import load_beacons
from scenes.view import camera_names
from studies.cli import options as opt
from studies.cli.common import print_table


def beacons(json_out: opt.Json = False) -> None:
    """List the beacon designs and their marker geometry."""
    rows = []
    for b in load_beacons().values():
        rows.append(
            {
                "name": b.name,
                "description": b.description,
                "d_t_mm": b.d_t_m * 1e3,
                "lit_face_diameter_mm": b.lit_face_diameter_m * 1e3,
                "markers": [
                    {"id": m.id, "position_mm": (m.position_m * 1e3).round(3).tolist(), "led_axis": m.normal.tolist()}
                    for m in b.markers
                ],
            }
        )
    if json_out:
        print(json.dumps(rows, indent=2))
        return
    print_table(
        "Beacon designs (target frame: x toward viewer, y viewer's left, z down; mm)",
        ("name", "marker", "position (x, y, z) mm", "LED axis", "description"),
        [
            (
                r["name"],
                str(m["id"]),
                "({:.0f}, {:.0f}, {:.0f})".format(*m["position_mm"]),
                "({:+.0f}, {:+.0f}, {:+.0f})".format(*m["led_axis"]),
                r["description"] if m["id"] == 1 else "",
            )
            for r in rows
            for m in r["markers"]
        ],
    )


def camera_rows() -> list[dict]:
    """Key figures of every camera."""
    rows = []
    for name in camera_names():
        c = load_camera(name)
        g, s = c.geometry, c.sensor
        rows.append(
            {
                "name": name,
                "description": g.description,
                "width_px": g.width_px,
                "height_px": g.height_px,
                "pixel_pitch_um": g.pixel_pitch_um,
                "focal_length_mm": round(g.focal_length_mm, 4),
                "horizontal_fov_deg": round(g.horizontal_fov_deg, 2),
                "pixel_angle_mrad": round(1e3 / g.focal_length_px, 4),
                "f_number": c.lens.f_number,
                "distortion": c.lens.distortion_model,
                "peak_qe_green": round(float(s.qe_rgb[1].max()), 3),
                "full_well_e": s.full_well_e,
                "adc_bits": s.adc_bits,
                "exposure_mode": c.exposure.mode,
                "jpeg": f"q{c.isp.jpeg_quality} {c.isp.chroma_subsampling}",
            }
        )
    return rows


def cameras(json_out: opt.Json = False) -> None:
    """List the camera models with their key figures (grid, lens, sensor, exposure, JPEG)."""
    rows = camera_rows()
    if json_out:
        print(json.dumps(rows, indent=2))
        return
    print_table(
        "Cameras",
        ("name", "resolution", "pixel µm", "focal mm", "HFOV °", "f/", "QE", "well e⁻", "bits", "exposure", "JPEG"),
        [
            (
                r["name"],
                f"{r['width_px']}×{r['height_px']}",
                f"{r['pixel_pitch_um']:g}",
                f"{r['focal_length_mm']:.2f}",
                f"{r['horizontal_fov_deg']:.1f}",
                f"{r['f_number']:g}",
                f"{r['peak_qe_green']:.2f}",
                f"{r['full_well_e']:.0f}",
                str(r["adc_bits"]),
                r["exposure_mode"],
                r["jpeg"],
            )
            for r in rows
        ],
    )


COMMANDS = {"beacons": beacons, "cameras": cameras}
