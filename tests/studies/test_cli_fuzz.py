"""Property-based fuzzing of every command's options: no input ends in a traceback.

For each command, hypothesis draws command lines from its own options (valid values, and
negative, zero, huge, NaN, infinite, empty, unknown names, path tricks like ``../../x``, random
text, unknown options, extra arguments, help flags) and runs them through
:func:`studies.cli.app.main` in this process, with every function that would start work
replaced by one raising :class:`~tests.helpers.cli.WorkStarted`. Each outcome must
be one of: work would start; a clean exit 0 (help, version, a listing); or exactly one line
``beacon-sim: error: ...`` on stderr with exit code 2, nothing on stdout and nothing created
under the sandbox. The run is bounded and deterministic: :data:`EXAMPLES` command lines per
command (``BEACON_SIM_FUZZ_EXAMPLES`` raises it for a longer search).
"""

from __future__ import annotations

import collections
import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.helpers.cli import invoke, patch_work

EXAMPLES = int(os.environ.get("BEACON_SIM_FUZZ_EXAMPLES", "25"))
"""Command lines drawn per command."""

REPO = Path(__file__).parents[2]

GENERAL = [
    "0", "-1", "1", "2", "3", "16", "100", "65537", "1000000000", str(2**31), str(2**64), "-0", "0.5", "-0.0",
    "1e308", "-1e308", "1e-320", "nan", "NaN", "inf", "-inf", "", " ", "abc", "x,y", "1,2", "1,,2", ",", "..",
    "../../x", "a/../b", "é", "--", "-", "-1,-2", "true",
]  # fmt: skip
"""Values tried for every option."""

OUT = ["o", "o/sub", "", " ", "../../o", "./o", "a/../o", "file", "file/sub", "/dev/null", "/proc/beacon-sim-x", "."]
"""``--out`` values: only ones that stay inside the sandbox or cannot be written (random
text could name ``/``)."""

SPECIFIC = {
    "camera": ["canon-t6-18mm", "canon-t6-10mm", "logitech-c270", "spedal-920", "nikon", "CANON-T6-18MM"],
    "cameras": ["canon-t6-18mm,logitech-c270", "spedal-920", "canon-t6-18mm,,", "nikon,canon-t6-18mm", "all"],
    "beacon": ["v1", "v2", "v3"],
    "side": ["red", "green", "blue", "yellow", "purple"],
    "environment": ["dark", "dark-room", "lit-room", "moon"],
    "housing": ["black", "white", "grey"],
    "paper-colour": ["white", "matched", "red", "pink"],
    "paper-sheets": ["0", "5", "6"],
    "range-m": ["0.05", "0.3", "1", "5", "20", "1000"],
    "yaw-deg": ["-90", "90", "91", "45"],
    "camera-height-m": ["0.1", "-0.1", "10"],
    "led-current-ma": ["2", "20", "30", "1000"],
    "spp": ["1", "4", "65536", "65537"],
    "oversampling": ["1", "3", "8", "9"],
    "seed": ["0", "542362", "542363"],
    "iso": ["100", "6400", "12800", "50"],
    "gain": ["0", "255", "256"],
    "exposure-s": ["0.01", "30", "60", "0.00001"],
    "f-number": ["3.5", "0.4", "22"],
    "wavelength-nm": ["380", "530", "720", "1000"],
    "ranges-m": ["2,5", "0", "-1,2", "nan", "1e9", "2,,5"],
    "currents-ma": ["5,20", "0", "1000", "inf"],
    "seeds": ["1", "3", "10000", "10001"],
    "workers": ["1", "2", "8", "9"],
    "scheduler": ["tcp://127.0.0.1:1", "nowhere", "tcp://:0", "127.0.0.1:99999", "tcp://[::1]:1"],
    "calibration": [str(REPO / "results/unknowns-search/samples.csv"), "missing.csv", "file", ""],
    "points": ["1", "2", "1000000"],
    "samples": ["1", "64", "65536", "65537"],
    "model": ["rational", "standard", "fisheye", "pinhole"],
    "scale": ["1", "4", "16", "17"],
    "view-deg": ["0", "10", "89", "90"],
    "brute-spp": ["2", "1024", "65536", "65537"],
    "brute-passes": ["2", "32", "4096", "4097"],
    "near-field-spp": ["2", "256", "1048576"],
    "sigma-px": ["0.3", "1e-7", "100", "101"],
    "trials": ["2", "500", "1000000", "1000001"],
    "tracker": ["thesis", "best", "nope"],
    "estimator": ["thesis", "best", "nope"],
    "alpha": ["0", "1", "2"],
    "crop-origin": ["0,0", "10,20", "1,2,3", "a,b"],
    "ring-camera": ["0", "1", "6", "7"],
    "pattern": ["8x6", "0x0", "x", "8X6"],
    "square-mm": ["24.4", "0", "-1"],
    "name": ["webcam-vs-dslr", "brightness-diffuser", "range-limit", "replication", "nope"],
    "image": ["missing.png", "file", "o"],
    "images": ["missing.png", "file"],
}
"""Valid and nearly valid values by option (or argument) name, to reach each command's deeper checks."""

TEXT = st.text(st.characters(exclude_categories=("Cs",), exclude_characters="\x00"), max_size=12)


def _values(param) -> st.SearchStrategy[str]:
    key = max(param.opts, key=len).lstrip("-") if param.param_type_name == "option" else param.name
    if key == "out":
        return st.sampled_from(OUT)
    if key in ("image", "images", "calibration"):  # read-only paths: curated (random text could be anything)
        return st.sampled_from(SPECIFIC[key] + ["", "..", "../../x", "/dev/null", "/"])
    specific = st.sampled_from(SPECIFIC.get(key, ["1"]))
    return st.one_of(  # mostly a valid or nearly valid value, to reach the deeper checks
        specific,
        specific,
        specific,
        st.sampled_from(GENERAL),
        st.integers(-(2**70), 2**70).map(str),
        st.floats(allow_nan=True, allow_infinity=True).map(repr),
        TEXT,
    )


@st.composite
def command_lines(draw, name: str, command) -> list[str]:
    """A command line of ``command``: some of its options in any order, maybe an extra token."""
    positional: list[str] = []
    chunks: list[list[str]] = []
    for param in command.params:
        if param.param_type_name == "argument":
            if draw(st.integers(0, 9)) > 0:
                count = draw(st.integers(1, 2)) if param.nargs == -1 else 1
                positional += [draw(_values(param)) for _ in range(count)]
            continue
        include = draw(st.integers(0, 9)) > 0 if param.required else draw(st.integers(0, 3)) == 0  # 90 %, 25 %
        if not include:
            continue
        if getattr(param, "is_flag", False):
            chunks.append([draw(st.sampled_from([*param.opts, *param.secondary_opts]))])
        else:
            flag = draw(st.sampled_from(param.opts))
            value = draw(_values(param))
            chunks.append([f"{flag}={value}"] if draw(st.integers(0, 7)) == 0 else [flag, value])
    chunks = draw(st.permutations(chunks))
    extra = draw(st.sampled_from([[]] * 12 + [["--bogus"], ["extra"], ["-h"], ["--help"], ["--out"], ["-x", "1"]]))
    return [name, *positional, *[token for chunk in chunks for token in chunk], *extra]


def _tree(root: Path) -> set[Path]:
    return set(root.rglob("*"))


def _command_names() -> list[str]:
    import typer

    from studies.cli.app import app

    return list(typer.main.get_command(app).commands)


COMMANDS = _command_names()


@pytest.mark.parametrize("name", COMMANDS)
def test_fuzzed_options_never_end_in_a_traceback(name, tmp_path, monkeypatch):
    import typer

    from studies.cli.app import app

    command = typer.main.get_command(app).commands[name]
    patch_work(monkeypatch)
    root = tmp_path / "sandbox"
    cwd = root / "a" / "b" / "c"
    cwd.mkdir(parents=True)
    (cwd / "file").write_text("not an image, not a folder")
    monkeypatch.chdir(cwd)
    outcomes: collections.Counter[str] = collections.Counter()

    @settings(
        max_examples=EXAMPLES,
        deadline=None,
        derandomize=True,
        database=None,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    )
    @given(args=command_lines(name, command))
    def check(args: list[str]) -> None:
        before = _tree(root)
        try:
            code, out, err = invoke(args)
        except Exception as exc:  # a traceback: the finding
            raise AssertionError(f"beacon-sim {args!r} raised {type(exc).__name__}: {exc}") from exc
        outcomes[str(code)] += 1
        assert code in ("work", 0, 2), (args, code, err[-2000:])
        if code == 2:
            lines = err.strip().splitlines()
            assert len(lines) == 1 and lines[0].startswith("beacon-sim: error: "), (args, err)
            assert out == "", (args, out[:500])
            assert _tree(root) == before, (args, sorted(map(str, _tree(root) - before)))

    check()
    print(f"{name}: {sum(outcomes.values())} command lines, outcomes {dict(outcomes)}")
    assert sum(outcomes.values()) >= min(EXAMPLES, 10)


# -- issue 26: duplicated list values and image headers ---------------------------------

LIST_OPTIONS = {
    "ranges-m": ["2", "4", "4.0", "6.5", "8"],
    "currents-ma": ["5", "10", "20", "20.0"],
    "cameras": ["canon-t6-18mm", "canon-t6-10mm", "logitech-c270", "spedal-920"],
    "beacons": ["v1", "v2"],
}
"""List options of ``study`` and values that are valid on their own."""


@settings(max_examples=EXAMPLES * 2, deadline=None, derandomize=True, database=None)
@given(
    option=st.sampled_from(sorted(LIST_OPTIONS)),
    data=st.data(),
)
def test_fuzzed_duplicated_list_values_are_refused_in_one_line(option, data, tmp_path_factory):
    values = data.draw(st.lists(st.sampled_from(LIST_OPTIONS[option]), min_size=2, max_size=6))
    repeated = len({float(v) if option in ("ranges-m", "currents-ma") else v for v in values}) < len(values)
    with pytest.MonkeyPatch.context() as mp:
        patch_work(mp)
        mp.chdir(tmp_path_factory.mktemp("dup"))
        code, out, err = invoke(["study", "range-limit", "--quick", "--out", "o", f"--{option}", ",".join(values)])
    if repeated:
        lines = err.strip().splitlines()
        assert code == 2 and len(lines) == 1 and lines[0].startswith(f"beacon-sim: error: {option}:"), (values, err)
        assert "more than once" in lines[0] and out == ""
    else:
        assert code in ("work", 2) and "Traceback" not in err, (values, err)


@st.composite
def image_headers(draw) -> bytes:
    """A PNG, JPEG or TIFF header claiming any size, maybe cut short or followed by junk."""
    from tests.studies.test_hostile_inputs import jpeg_header, png_header, tiff_header

    width = draw(st.one_of(st.integers(0, 80), st.integers(0, 2**16 - 1), st.integers(0, 2**31)))
    height = draw(st.one_of(st.integers(0, 80), st.integers(0, 2**16 - 1), st.integers(0, 2**31)))
    kind = draw(st.sampled_from(["png", "jpeg", "tiff"]))
    if kind == "png":
        blob = png_header(min(width, 2**31 - 1), min(height, 2**31 - 1), draw(st.sampled_from([8, 16])))
    elif kind == "jpeg":
        blob = jpeg_header(min(width, 2**16 - 1), min(height, 2**16 - 1))
    else:
        blob = tiff_header(min(width, 2**32 - 1), min(height, 2**32 - 1))
    cut = draw(st.integers(0, len(blob)))
    return blob[: draw(st.sampled_from([len(blob), cut]))] + draw(st.binary(max_size=64))


@settings(max_examples=EXAMPLES * 8, deadline=None, derandomize=True, database=None)
@given(blob=image_headers())
def test_fuzzed_image_headers_never_decode_too_large(blob, tmp_path_factory):
    import pipeline.image_io as image_io
    from pipeline.image_header import header_size

    path = tmp_path_factory.mktemp("img") / "fuzz.img"
    path.write_bytes(blob)
    header = header_size(path)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(image_io, "MAX_PIXELS", 4096)  # decoding stays cheap: at most 64 × 64 px
        real = image_io.cv2.imdecode

        def guarded(*args, **kwargs):
            assert header is not None and 0 < header.pixels <= 4096, "decoded past the header check"
            return real(*args, **kwargs)

        mp.setattr(image_io.cv2, "imdecode", guarded)
        try:
            image = image_io.load_image(path)
        except ValueError as exc:
            assert str(exc).startswith("image: ") and "\n" not in str(exc), str(exc)
        else:
            assert image.shape[0] * image.shape[1] <= 4096
