"""The hardware: ``beacons`` and ``cameras`` (a table, ``--json``, or ``--template`` for a file
of your own), and the user's hardware files (``--camera-file`` / ``--beacon-file``).

A hardware file option may stand anywhere on the command line and applies to every command:
:func:`use_hardware_files` takes it out of the arguments, reads the file once with every file
it names (:mod:`scenes.hardware`: the run and its workers use those contents, never the path),
checks it field by field (one-line errors naming the file and field; a key nothing reads names
the nearest valid key) and registers its name. When the command takes a camera (``--camera`` / ``--cameras``) or a
beacon (``--beacon`` / ``--beacons``) and the command line does not name one, the file's
hardware is used.
"""

from __future__ import annotations

from typing import Annotated

import typer

from camera_models.camera import camera_template, load_camera
from scenes.beacon import beacon_design, beacon_template, load_beacons
from scenes.hardware import add_hardware_file, is_builtin
from scenes.view import camera_names
from studies.cli import options as opt
from studies.cli.common import UsageError, print_table
from studies.engine import strict_json

__all__ = [
    "COMMANDS",
    "HARDWARE_FILE_OPTIONS",
    "SELECTING_OPTIONS",
    "beacons",
    "camera_rows",
    "cameras",
    "use_hardware_files",
]

HARDWARE_FILE_OPTIONS = {"--camera-file": "camera", "--beacon-file": "beacon"}
"""The hardware-file options and the kind of hardware each adds."""

SELECTING_OPTIONS = {"camera": ("--camera", "--cameras"), "beacon": ("--beacon", "--beacons")}
"""The options by which a command names its camera or beacon (a single name, or a comma list)."""

Template = Annotated[bool, typer.Option("--template", help="Print a complete file to copy and edit, then exit.")]


def use_hardware_files(args: list[str], commands: dict) -> list[str]:
    """Register the hardware files named in ``args`` and return the remaining arguments.

    Parameters
    ----------
    args
        Command-line arguments after the program name.
    commands
        The app's click commands by name (the options of the command ``args`` runs decide
        where a file's hardware is filled in).

    Returns
    -------
    list of str
        ``args`` without the hardware-file options, with ``--camera NAME`` (or
        ``--cameras NAME,...``) and ``--beacon NAME`` (``--beacons``) added where the command
        takes them and the command line names none.
    """
    rest: list[str] = []
    added: dict[str, list[str]] = {"camera": [], "beacon": []}
    i = 0
    while i < len(args):
        option, eq, value = args[i].partition("=")
        if option not in HARDWARE_FILE_OPTIONS:
            rest.append(args[i])
            i += 1
            continue
        if not eq:
            if i + 1 >= len(args):
                raise UsageError(f"{option[2:]}: expected a path to a TOML file after {option}")
            value, i = args[i + 1], i + 1
        i += 1
        kind = HARDWARE_FILE_OPTIONS[option]
        added[kind].append(_register(kind, value))
    command = next((commands.get(a) for a in rest if not a.startswith("-")), None)
    if command is not None:
        given = {a.partition("=")[0] for a in rest}
        names = {o for p in command.params for o in getattr(p, "opts", ())}
        for kind, found in added.items():
            single, several = SELECTING_OPTIONS[kind]
            if not found or given & {single, several}:
                continue
            if several in names:
                rest += [several, ",".join(found)]
            elif single in names and len(found) == 1:
                rest += [single, found[0]]
    return rest


def _register(kind: str, path: str) -> str:
    """Add one hardware file and load it completely, so every field is checked now."""
    try:
        name = add_hardware_file(kind, path)
        load_camera(name) if kind == "camera" else beacon_design(name)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    return name


def beacons(
    json_out: opt.Json = False,
    template: Template = False,
    like: Annotated[str, typer.Option("--like", help="Beacon the template starts from.")] = "v2",
) -> None:
    """List the beacon designs and their marker geometry (or print a template beacon file)."""
    if template:
        print(beacon_template(_builtin("beacon", like)), end="")
        return
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
        print(strict_json.dumps(rows, indent=2))
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
                "jpeg": (
                    f"q{c.isp.jpeg_quality} {c.isp.chroma_subsampling}"
                    if c.isp.output == "jpeg"
                    else f"none ({c.isp.output.upper()})"  # an uncompressed frame (isp.output)
                ),
                "output": c.isp.output,
            }
        )
    return rows


def _builtin(kind: str, name: str) -> str:
    if not is_builtin(kind, name):
        raise UsageError(f"like: expected a built-in {kind}, got {name!r}")
    return name


def cameras(
    json_out: opt.Json = False,
    template: Template = False,
    like: Annotated[str, typer.Option("--like", help="Camera the template starts from.")] = "canon-t6-18mm",
) -> None:
    """List the camera models with their key figures (or print a template camera file)."""
    if template:
        print(camera_template(_builtin("camera", like)), end="")
        return
    rows = camera_rows()
    if json_out:
        print(strict_json.dumps(rows, indent=2))
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
