"""Property-based fuzzing of the inputs issue 26's hostile user broke: hardware files and ``--out``.

Two families of inputs, each drawn by hypothesis and run through :func:`studies.cli.app.main` in
this process (``tests.helpers.cli``'s :func:`invoke`, with every work function replaced by
:func:`patch_work`, so nothing renders):

* **Hardware files** (``--camera-file`` / ``--beacon-file``). Documents start from a valid file
  (``cameras --template``, a built-in camera that names a ``body``, the documented example that
  names a spectral-sensitivity CSV beside it, ``beacons --template``) and are mutated: keys
  misspelt, deleted or added, values replaced by huge, negative, zero, NaN, infinite or
  wrong-typed ones, subtrees wrapped in deep nesting; or replaced by raw text (cut short, not
  UTF-8, nested thousands deep, over the 1 MiB limit); or named through links, folders, FIFOs,
  loops and missing paths; the files they name (``body``, ``sensor.ssf_csv``) missing, linked,
  folders or garbage CSV. The cheapest command that fully checks a file is ``cameras --json`` /
  ``beacons --json`` (the file is read and loaded field by field when the option is taken out of
  the command line, then every derived figure is listed); a file that passes it is then given
  to ``capture`` and ``render`` up to the point where work would start. Property: exit 0 (with
  strict JSON listing the file's hardware), or exactly one line ``beacon-sim: error: ...`` with
  exit 2 naming the file, never a traceback, in bounded time and memory; a misspelt key is an
  error naming it.
* **Output folders** (``--out``). A sandbox with a *victim* tree beside the working folder; the
  drawn ``--out`` is missing, empty, a link (to an empty folder elsewhere, dangling, a loop), a
  file, a FIFO, a folder holding foreign files, another command's or the same command's
  results, unwritable, or a system folder, and may hold links (to the victim's files and
  folders, relative and absolute, at any depth) and hard links to the victim's files.
  Property: the victim tree is byte-for-byte, mode and link unchanged (``--force`` or not);
  every refusal is one line with exit 2; no traceback.

Duplicated list values and image headers are fuzzed in ``test_cli_fuzz.py``.

The run is bounded and deterministic (``derandomize=True``): :data:`EXAMPLES` cases per test
family member (25 by default, about 30 s in all on two cores). ``BEACON_SIM_FUZZ_EXAMPLES=N``
sets it for a longer campaign, e.g.::

    BEACON_SIM_FUZZ_EXAMPLES=1000 nice -n 19 .venv/bin/python -m pytest -q -s \\
        tests/studies/test_fuzz_inputs.py tests/studies/test_cli_fuzz.py
"""

from __future__ import annotations

import collections
import datetime
import hashlib
import json
import math
import os
import resource
import shutil
import stat
import time
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.helpers.cli import REPO, invoke, patch_work

EXAMPLES = int(os.environ.get("BEACON_SIM_FUZZ_EXAMPLES", "25"))
"""Cases drawn per test (``BEACON_SIM_FUZZ_EXAMPLES`` sets it)."""

CASE_LIMIT_S = 30.0
"""Longest one case may take (a file that made a check run unbounded would exceed it)."""

MEMORY_LIMIT_BYTES = 2 << 30
"""Most the process's peak resident memory may grow during one test (a file accepted with a
100000 x 100000 sensor, or decoded past a limit, would exceed it)."""

FUZZ_SETTINGS = settings(
    max_examples=EXAMPLES,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much],
)

# -- TOML written from values ------------------------------------------------------------


def _toml_string(text: str) -> str:
    out = ['"']
    for ch in text:
        code = ord(ch)
        if ch in '"\\':
            out.append("\\" + ch)
        elif code < 0x20 or code == 0x7F:
            out.append(f"\\u{code:04x}")
        else:
            out.append(ch)
    return "".join(out) + '"'


def toml_value(value: object) -> str:
    """``value`` as one TOML value (tables inline), NaN and infinities included."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return _toml_string(value)
    if isinstance(value, datetime.date | datetime.time):
        return value.isoformat()
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{_toml_string(k)} = {toml_value(v)}" for k, v in value.items()) + "}"
    raise TypeError(type(value))


def toml_document(values: dict) -> str:
    """A TOML document of ``values``: one ``key = value`` line per top-level key."""
    return "".join(f"{_toml_string(k)} = {toml_value(v)}\n" for k, v in values.items())


# -- the valid documents mutations start from ----------------------------------------------

CSV_NAME = "mine.csv"
"""The spectral-sensitivity CSV a fuzzed camera may name beside itself."""


def _seeds() -> dict[str, tuple[str, dict]]:
    """Valid documents by label: (kind, parsed values), each renamed so it is not a built-in."""
    import tomllib

    from camera_models.camera import camera_template
    from scenes.beacon import beacon_template

    seeds = {
        "camera template": ("camera", tomllib.loads(camera_template("canon-t6-18mm"))),
        "webcam template": ("camera", tomllib.loads(camera_template("logitech-c270"))),
        "camera with a body": ("camera", tomllib.loads((REPO / "camera_models/data/canon-t6-10mm.toml").read_text())),
        "camera with its own csv": ("camera", tomllib.loads((REPO / "docs/examples/rpi-hq-6mm.toml").read_text())),
        "beacon template": ("beacon", tomllib.loads(beacon_template("v2"))),
        "beacon v1 template": ("beacon", tomllib.loads(beacon_template("v1"))),
        "beacon example": ("beacon", tomllib.loads((REPO / "docs/examples/v2-arms-100mm.toml").read_text())),
    }
    seeds["camera with its own csv"][1]["sensor"]["ssf_csv"] = CSV_NAME
    for label, (_kind, values) in seeds.items():
        values["name"] = "fuzz-" + label.replace(" ", "-")
    return seeds


SEEDS = _seeds()

WEIRD_NUMBERS = [
    0, -1, 1, 2, -0.0, 0.5, 1e-300, 5e-324, 1e308, -1e308, 1e30, -1e30, 2**31, 2**63 - 1, 2**63, -(2**63), 2**64,
    10**400, -(10**400), math.nan, math.inf, -math.inf, 16, 20000, 20001, 1e-9, 3.0, 65535,
]  # fmt: skip
"""Numbers every numeric field meets: zero, signs, the ends of float and int64, NaN, infinities."""

WEIRD_OTHER = [
    True, False, "", " ", "x", "nan", "1", "inf", "..", "../../etc/passwd", "/etc/passwd", "é" * 3, "x" * 5000,
    [], [[]], [1, 2, 3], [math.nan], [1, "a"], {}, {"value": 1}, {"value": 1, "source": "s", "assumed": "a"},
    {"value": [1, 2], "assumed": "a list"}, {"assumed": "no value"}, datetime.date(1979, 5, 27),
    datetime.datetime(1979, 5, 27, 7, 32, tzinfo=datetime.UTC), datetime.time(7, 32),
]  # fmt: skip
"""Values of the wrong type, empty ones, paths, provenance tables that are not quite right."""

TEXT = st.text(st.characters(exclude_categories=("Cs",)), max_size=12)
NUMBER = st.one_of(
    st.sampled_from(WEIRD_NUMBERS),
    st.integers(-(2**70), 2**70),
    st.floats(allow_nan=True, allow_infinity=True),
)
WEIRD = st.one_of(NUMBER, NUMBER, st.sampled_from(WEIRD_OTHER), TEXT)


def _paths(node: object, prefix: tuple = ()) -> list[tuple]:
    """Every path (keys and list indices) into ``node``, parents before children."""
    out = []
    children = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()
    for key, child in children:
        out.append((*prefix, key))
        out += _paths(child, (*prefix, key))
    return out


def _parent(values: dict, path: tuple) -> object:
    node: object = values
    for key in path[:-1]:
        node = node[key]  # type: ignore[index]
    return node


def _misspelt(draw, key: str, siblings) -> str:
    """``key`` with one typing mistake, a name none of its siblings has."""
    ways = ["drop", "swap", "double", "insert", "case", "suffix", "prefix", "space"]
    for _ in range(20):
        way = draw(st.sampled_from(ways))
        i = draw(st.integers(0, max(len(key) - 1, 0)))
        if way == "drop" and len(key) > 1:
            new = key[:i] + key[i + 1 :]
        elif way == "swap" and len(key) > 1:
            i = min(i, len(key) - 2)
            new = key[:i] + key[i + 1] + key[i] + key[i + 2 :]
        elif way == "double":
            new = key[: i + 1] + key[i:]
        elif way == "insert":
            new = key[:i] + draw(st.sampled_from("aeiouxz_-")) + key[i:]
        elif way == "case":
            new = key.upper() if key != key.upper() else key.lower() + "x"
        elif way == "suffix":
            new = key + draw(st.sampled_from(["s", "_mm", "_m", "2", "_"]))
        elif way == "prefix":
            new = draw(st.sampled_from(["_", "my_", "x"])) + key
        else:
            new = key + " "
        if new and new != key and new not in siblings:
            return new
    return key + "_fuzz"


OPERATIONS = ["rename", "rename", "value", "value", "value", "replace", "delete", "add", "wrap"]
"""Mutations, weighted: misspelt keys and numbers' values most often."""

FREE_NAMES = ("processing_options",)
"""Tables whose keys are names the file chooses (a misspelling there defines another option)."""


@st.composite
def mutated_documents(draw) -> tuple[str, str, dict, list[tuple[str, tuple, str]]]:
    """(seed label, kind, mutated values, mutations as (operation, path, new key or ''))."""
    import copy

    label = draw(st.sampled_from(sorted(SEEDS)))
    kind, seed = SEEDS[label]
    values = copy.deepcopy(seed)
    done: list[tuple[str, tuple, str]] = []
    for _ in range(draw(st.integers(1, 3))):
        paths = [p for p in _paths(values) if p != ("name",)]
        if not paths:
            break
        operation = draw(st.sampled_from(OPERATIONS))
        if operation == "value":  # a number's value: the commonest field of all
            numbers = [p for p in paths if p[-1] == "value"]
            path = draw(st.sampled_from(numbers or paths))
        else:
            path = draw(st.sampled_from(paths))
        parent = _parent(values, path)
        key = path[-1]
        if operation == "rename":
            if isinstance(parent, dict):
                new = _misspelt(draw, key, parent)
                parent[new] = parent.pop(key)
                done.append(("rename", path, new))
        elif operation in ("value", "replace"):
            parent[key] = draw(NUMBER if operation == "value" and draw(st.booleans()) else WEIRD)
            done.append((operation, path, ""))
        elif operation == "delete":
            del parent[key]
            done.append(("delete", path, ""))
        elif operation == "add":
            node = parent[key]
            if isinstance(node, dict):
                siblings = list(node)
                new = _misspelt(draw, draw(st.sampled_from(siblings)), node) if siblings else "fuzz"
                node[new] = draw(WEIRD)
                done.append(("add", (*path, new), new))
        else:  # wrap: nested in tables and arrays, up to past the 16 levels a data file may have
            node = parent[key]
            for level in range(draw(st.integers(1, 40))):
                node = [node] if draw(st.booleans()) else {f"n{level}": node}
            parent[key] = node
            done.append(("wrap", path, ""))
    return label, kind, values, done


@st.composite
def csv_contents(draw) -> bytes:
    """A spectral-sensitivity CSV: valid, cut, garbage cells, NaN, negatives, one row, huge, binary."""
    kind = draw(st.sampled_from(["valid", "cells", "cut", "header", "rows", "binary", "empty", "big"]))
    good = (REPO / "camera_models/data/ssf/sony_ilce_6400.csv").read_bytes()
    if kind == "valid":
        return good
    lines = good.decode().splitlines()
    if kind == "cells":
        for _ in range(draw(st.integers(1, 4))):
            row = draw(st.integers(0, len(lines) - 1))
            cells = lines[row].split(",")
            cell = draw(st.integers(0, len(cells) - 1))
            cells[cell] = draw(st.sampled_from(["nan", "inf", "-1", "", "x", "1e400", "-0", "1,2", '"', "0x10"]))
            lines[row] = ",".join(cells)
        return ("\n".join(lines) + "\n").encode()
    if kind == "cut":
        return good[: draw(st.integers(0, len(good)))]
    if kind == "header":
        headers = ["", "wavelength_nm,r,g", "a,b,c,d", "wavelength_nm,r,g,b,b", "\ufeff" + lines[0]]
        lines[0] = draw(st.sampled_from(headers))
        return ("\n".join(lines) + "\n").encode()
    if kind == "rows":
        body = lines[1:]
        body = draw(st.sampled_from([body[:1], body[::-1], body + body, [], body[:2] * 3]))
        return ("\n".join([lines[0], *body]) + "\n").encode()
    if kind == "binary":
        return draw(st.binary(max_size=256))
    if kind == "empty":
        return b""
    return (lines[0] + "\n" + "500,0.1,0.2,0.3\n" * 70000).encode()  # ~1.1 MB: over the limit


RAW_KINDS = ["cut", "bytes", "not utf-8", "nested arrays", "nested tables", "dotted keys", "huge", "long string"]


@st.composite
def raw_documents(draw) -> tuple[str, bytes]:
    """(kind, bytes) of a hardware file that is not a mutated valid document."""
    kind = draw(st.sampled_from(["camera", "beacon"]))
    label = "camera template" if kind == "camera" else "beacon template"
    text = toml_document(SEEDS[label][1])
    how = draw(st.sampled_from(RAW_KINDS))
    depth = draw(st.sampled_from([17, 100, 999, 1000, 5000, 100_000]))
    if how == "cut":
        data = text.encode()[: draw(st.integers(0, len(text)))]
    elif how == "bytes":
        data = draw(st.binary(max_size=512))
    elif how == "not utf-8":
        data = text.encode()[:200] + b"\xff\xfe\x80" + text.encode()[200:]
    elif how == "nested arrays":
        data = (text + "deep = " + "[" * depth + "1" + "]" * depth + "\n").encode()
    elif how == "nested tables":
        data = (text + "deep = " + "{a = " * depth + "1" + "}" * depth + "\n").encode()
    elif how == "dotted keys":
        data = (text + ".".join(["a"] * depth) + " = 1\n").encode()
    elif how == "huge":
        data = (text + "# " + "x" * (1 << 20) + "\n").encode()
    else:
        data = text.replace('description = "', 'description = "' + "é" * 200_000, 1).encode()
    return kind, data


# -- running one case ----------------------------------------------------------------------


def _run(args: list[str]) -> tuple[int | str, str, str, float]:
    """``invoke(args)`` with a fresh registry of user files; a traceback fails the test."""
    from scenes.hardware import clear_user_hardware

    clear_user_hardware()
    start = time.monotonic()
    try:
        code, out, err = invoke(args)
    except Exception as exc:  # a traceback: the finding
        raise AssertionError(f"beacon-sim {args!r} raised {type(exc).__name__}: {exc}") from exc
    finally:
        clear_user_hardware()
    elapsed = time.monotonic() - start
    assert elapsed < CASE_LIMIT_S, (args, elapsed)
    return code, out, err, elapsed


def _one_line(code, err: str, args) -> str:
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("beacon-sim: error: "), (args, code, err[-3000:])
    return lines[0]


def _strict_json(text: str) -> object:
    def refuse(constant: str) -> None:
        raise AssertionError(f"not strict JSON: {constant}")

    return json.loads(text, parse_constant=refuse)


def _max_rss_bytes() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


LISTING = {"camera": ["cameras", "--json"], "beacon": ["beacons", "--json"]}
"""The cheapest command that fully checks a file of each kind."""

DOWNSTREAM = {
    "camera": [["capture", "--out", "o"], ["render", "--out", "r", "--range-m", "3"]],
    "beacon": [["render", "--out", "r", "--range-m", "3"], ["capture", "--out", "o", "--range-m", "0.3"]],
}
"""Commands a file that passed the listing is then given to, up to the point work would start."""


def check_hardware_file(kind: str, path: Path, outcomes: collections.Counter, label: str | None = None) -> str:
    """Run the listing with ``path`` as the ``kind`` file and check the property; return the error or ''."""
    option = f"--{kind}-file"
    args = [option, str(path), *LISTING[kind]]
    code, out, err, _ = _run(args)
    outcomes[f"listing {code}"] += 1
    if code != 0:
        line = _one_line(code, err, args)
        assert out == "", (args, out[:300])
        named = label or path.name
        assert named in line or option[2:] in line, (args, line)
        return line
    assert "Traceback" not in err, (args, err)
    rows = _strict_json(out)
    import tomllib

    name = tomllib.loads(path.read_text(encoding="utf-8"))["name"]
    assert name in {row["name"] for row in rows}, (args, name)  # type: ignore[index, union-attr]
    for command in DOWNSTREAM[kind]:
        args = [option, str(path), *command]
        code, out, err, _ = _run(args)
        outcomes[f"{command[0]} {code}"] += 1
        assert code in ("work", 0, 2), (args, code, err[-3000:])
        if code == 2:
            _one_line(code, err, args)
    return ""


def _sandbox(tmp_path: Path, monkeypatch) -> Path:
    patch_work(monkeypatch)
    home = tmp_path / "cwd"
    home.mkdir()
    monkeypatch.chdir(home)
    return home


# -- hardware files --------------------------------------------------------------------------


@pytest.mark.filterwarnings("error::RuntimeWarning")  # NaN or inf computed from a file: a finding
def test_fuzzed_hardware_documents_end_in_one_line_or_load(tmp_path, monkeypatch):
    """Mutations of valid camera and beacon files: loaded, or one line naming the file; a
    misspelt or added key is an error naming it."""
    home = _sandbox(tmp_path, monkeypatch)
    (home / CSV_NAME).write_bytes((REPO / "camera_models/data/ssf/sony_ilce_6400.csv").read_bytes())
    outcomes: collections.Counter[str] = collections.Counter()
    rss = _max_rss_bytes()

    @FUZZ_SETTINGS
    @given(case=mutated_documents())
    def check(case) -> None:
        label, kind, values, done = case
        path = home / "fuzz.toml"
        path.write_text(toml_document(values), encoding="utf-8")
        line = check_hardware_file(kind, path, outcomes)
        for operation, where, new in done:
            free = len(where) >= 2 and where[-2] in FREE_NAMES
            if operation in ("rename", "add") and not free and len(done) == 1:
                assert line, f"{label}: {operation} of {'.'.join(map(str, where))} to {new!r} was accepted"
                assert new in line or str(where[-1]) in line, (label, where, new, line)

    check()
    print(f"hardware documents: {sum(outcomes.values())} commands, outcomes {dict(outcomes)}")
    assert _max_rss_bytes() - rss < MEMORY_LIMIT_BYTES
    assert outcomes["listing 0"] > 0 and outcomes["listing 2"] > 0  # both ends reached


@pytest.mark.filterwarnings("error::RuntimeWarning")  # NaN or inf computed from a file: a finding
def test_fuzzed_raw_hardware_files_end_in_one_line(tmp_path, monkeypatch):
    """Files that are not a valid document at all: cut, binary, not UTF-8, nested 17 to 100000
    levels, over 1 MiB."""
    home = _sandbox(tmp_path, monkeypatch)
    outcomes: collections.Counter[str] = collections.Counter()
    rss = _max_rss_bytes()

    @FUZZ_SETTINGS
    @given(case=raw_documents())
    def check(case) -> None:
        kind, data = case
        path = home / "raw.toml"
        path.write_bytes(data)
        check_hardware_file(kind, path, outcomes)

    check()
    print(f"raw hardware files: {sum(outcomes.values())} commands, outcomes {dict(outcomes)}")
    assert _max_rss_bytes() - rss < MEMORY_LIMIT_BYTES


BODY_VALUES = ["canon-eos-1300d", "logitech-c270", "nikon-d750", "", "..", "../bodies/canon-eos-1300d", "/etc/passwd"]
CSV_VALUES = [CSV_NAME, "missing.csv", "sony_ilce_6400.csv", "../ssf/sony_ilce_6400.csv", "/etc/passwd", "", ".", "dir"]
BESIDE = [
    "file", "link to file", "link to outside file", "dangling link", "link loop", "folder", "fifo", "link to /dev/zero",
]  # fmt: skip


@st.composite
def named_file_cases(draw) -> tuple[str, str, str, bytes]:
    """(field, value, what stands beside the camera file under that name, its bytes)."""
    field = draw(st.sampled_from(["body", "sensor.ssf_csv"]))
    value = draw(st.sampled_from(BODY_VALUES if field == "body" else CSV_VALUES))
    beside = draw(st.sampled_from(BESIDE))
    return field, value, beside, draw(csv_contents())


def _place(folder: Path, name: str, what: str, data: bytes, outside: Path) -> None:
    """Put ``what`` at ``folder/name`` (a file with ``data``, a link, a folder, a FIFO)."""
    target = folder / name
    if not name or name in (".", "..") or "/" in name:
        return
    if what == "file":
        target.write_bytes(data)
    elif what == "link to file":
        (folder / "real.csv").write_bytes(data)
        target.symlink_to("real.csv")
    elif what == "link to outside file":
        outside.write_bytes(data)
        target.symlink_to(outside)
    elif what == "dangling link":
        target.symlink_to("nowhere.csv")
    elif what == "link loop":
        target.symlink_to(name)
    elif what == "folder":
        target.mkdir()
    elif what == "fifo":
        os.mkfifo(target)
    else:
        target.symlink_to("/dev/zero")


@pytest.mark.filterwarnings("error::RuntimeWarning")  # NaN or inf computed from a file: a finding
def test_fuzzed_files_a_camera_names_end_in_one_line_or_load(tmp_path, monkeypatch):
    """``body`` and ``sensor.ssf_csv`` naming missing files, links, loops, folders, FIFOs, paths
    and garbage CSV: loaded, or one line; never read past the limit nor blocked on a FIFO."""
    import copy

    home = _sandbox(tmp_path, monkeypatch)
    outcomes: collections.Counter[str] = collections.Counter()
    rss = _max_rss_bytes()
    outside = tmp_path / "outside.csv"

    @FUZZ_SETTINGS
    @given(case=named_file_cases())
    def check(case) -> None:
        field, value, beside, data = case
        folder = home / "hw"
        shutil.rmtree(folder, ignore_errors=True)
        folder.mkdir()
        values = copy.deepcopy(SEEDS["camera with a body" if field == "body" else "camera with its own csv"][1])
        if field == "body":
            values["body"] = value
        else:
            values["sensor"]["ssf_csv"] = value
        path = folder / "cam.toml"
        path.write_text(toml_document(values), encoding="utf-8")
        _place(folder, value + (".toml" if field == "body" else ""), beside, data, outside)
        check_hardware_file("camera", path, outcomes)

    check()
    print(f"named files: {sum(outcomes.values())} commands, outcomes {dict(outcomes)}")
    assert _max_rss_bytes() - rss < MEMORY_LIMIT_BYTES


HARDWARE_PATHS = [
    "missing.toml", "", ".", "..", "folder", "fifo", "loop", "dangling", "link", "/dev/zero", "/dev/null",
    "/proc/self/status", "/etc/passwd", "~nosuchuser/x.toml", "~/missing.toml", "a\nb", "big.toml", "link/x",
]  # fmt: skip
"""``--camera-file`` / ``--beacon-file`` values that are not a path to a hardware file."""


@settings(max_examples=max(EXAMPLES, 2 * len(HARDWARE_PATHS)), deadline=None, derandomize=True, database=None)
@given(value=st.sampled_from(HARDWARE_PATHS), kind=st.sampled_from(["camera", "beacon"]), eq=st.booleans())
def test_fuzzed_hardware_file_paths_end_in_one_line(value, kind, eq, tmp_path_factory):
    """Paths that are folders, FIFOs, devices, loops, missing, or name no user: one line, exit 2."""
    home = tmp_path_factory.mktemp("paths")
    (home / "folder").mkdir()
    os.mkfifo(home / "fifo")
    (home / "loop").symlink_to("loop")
    (home / "dangling").symlink_to("nowhere.toml")
    template = toml_document(SEEDS[f"{kind} template"][1])
    (home / "valid.toml").write_text(template)
    (home / "link").symlink_to("valid.toml")
    (home / "big.toml").write_text(template + "# " + "x" * (1 << 20) + "\n")
    with pytest.MonkeyPatch.context() as mp:
        patch_work(mp)
        mp.chdir(home)
        option = f"--{kind}-file"
        args = [f"{option}={value}"] if eq else [option, value]
        code, out, err, _ = _run([*args, *LISTING[kind]])
    if value == "link":
        assert code == 0 and _strict_json(out), err
    else:
        line = _one_line(code, err, args)
        assert f"{kind}-file" in line or value.split("/")[-1] in line or "/proc/" in line, line


# -- found by fuzzing: regression tests ----------------------------------------------------


def test_a_hardware_file_path_in_a_loop_of_links_is_one_line(tmp_path, monkeypatch):
    """``--camera-file loop`` (``loop -> loop``) ended in ``RuntimeError: Symlink loop``."""
    _sandbox(tmp_path, monkeypatch)
    Path("a").symlink_to("b")
    Path("b").symlink_to("a")
    code, out, err, _ = _run(["--camera-file", "a", "cameras", "--json"])
    assert _one_line(code, err, "a") == (
        "beacon-sim: error: camera-file: expected a TOML file, got a (a loop of symbolic links)"
    )
    assert out == ""


def test_a_hardware_file_under_an_unknown_users_home_is_one_line(tmp_path, monkeypatch):
    """``--beacon-file ~nosuchuser/x.toml`` ended in ``RuntimeError: Could not determine home directory``."""
    _sandbox(tmp_path, monkeypatch)
    code, _, err, _ = _run(["--beacon-file", "~nosuchuser/x.toml", "beacons", "--json"])
    assert _one_line(code, err, "~") == (
        "beacon-sim: error: beacon-file: expected a TOML file, got ~nosuchuser/x.toml (no such user's home folder)"
    )


@pytest.mark.parametrize("out", ["a", "a/sub"])
def test_an_out_folder_in_a_loop_of_links_is_one_line(tmp_path, monkeypatch, out):
    """``--out a`` with ``a -> b -> a`` ended in ``RuntimeError: Symlink loop``."""
    _sandbox(tmp_path, monkeypatch)
    Path("a").symlink_to("b")
    Path("b").symlink_to("a")
    code, _, err, _ = _run(["study", "range-limit", "--quick", "--out", out])
    assert _one_line(code, err, out) == (
        f"beacon-sim: error: out: expected a folder or a new name, got {out} "
        "(a loop of symbolic links; remove the link)"
    )
    assert sorted(p.name for p in Path().iterdir()) == ["a", "b"]


@pytest.mark.parametrize("kind", ["camera", "beacon"])
def test_a_dotted_key_of_100000_parts_is_refused_before_parsing(tmp_path, monkeypatch, kind):
    """``a.a.a....a = 1`` with 100 000 parts (a 200 kB file, under the 1 MiB limit) took Python's
    ``tomllib`` minutes and 40 GB (quadratic in the parts; the fuzz run was killed for memory).
    It is now refused by a linear scan, in one line, before the parser sees it."""
    _sandbox(tmp_path, monkeypatch)
    path = Path("deep.toml")
    path.write_text(toml_document(SEEDS[f"{kind} template"][1]) + ".".join(["a"] * 100_000) + " = 1\n")
    rss = _max_rss_bytes()
    code, out, err, elapsed = _run([f"--{kind}-file", str(path), *LISTING[kind]])
    assert _one_line(code, err, path) == (
        f"beacon-sim: error: {path.resolve()}: expected tables and arrays nested at most 16 deep, "
        "got a dotted key of 100000 parts"
    )
    assert out == "" and elapsed < 5 and _max_rss_bytes() - rss < 200 << 20


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        (
            "knee_um = { value = 10.0,",
            "knee_um = { value = 20000.0,",
            "optics.glare.outer_radius_mm: expected a number > knee_um / 1000 = 20 (the tail ends beyond its knee), "
            "got 13.4",
        ),
        (
            "fraction = { value = 0.02,",
            "fraction = { value = 1.0,",
            "optics.glare.fraction: expected a number >= 0 and < 1, got 1.0",
        ),
    ],
)
def test_glare_bounds_name_the_file_and_field(tmp_path, monkeypatch, old, new, message):
    """A glare knee beyond the tail's outer radius ended in ``glare.outer_radius_mm: expected >
    knee`` (no file, no full field, no bound); a fraction of 1 likewise."""
    _sandbox(tmp_path, monkeypatch)
    from camera_models.camera import camera_template

    text = camera_template("canon-t6-18mm").replace('name = "my-camera"', 'name = "glare"')
    assert old in text
    Path("g.toml").write_text(text.replace(old, new, 1))
    code, _, err, _ = _run(["--camera-file", "g.toml", "cameras", "--json"])
    assert _one_line(code, err, "g") == f"beacon-sim: error: camera file g.toml: {message}"


GOOD_CSV = "wavelength_nm,r,g,b\n380,0.1,0.2,0.3\n720,0.2,0.3,0.1\n"


@pytest.mark.parametrize(
    ("csv_text", "reason"),
    [
        (
            GOOD_CSV.replace("0.2,0.3,0.1", "0.2,0,0.1").replace("0.1,0.2,0.3", "0.1,0,0.3"),
            "g: expected a sensitivity > 0 somewhere in 380-720 nm, got none",
        ),
        (GOOD_CSV.replace("0.2,0.3", "nan,0.3", 1), "r, g, b: expected finite sensitivities >= 0"),
        (GOOD_CSV.replace("0.2,0.3,0.1", "-0.2,0.3,0.1"), "r, g, b: expected finite sensitivities >= 0"),
        (GOOD_CSV.replace("720,", "380,"), "wavelength_nm: expected finite wavelengths in increasing order, each once"),
        ("wavelength_nm,r,g,b\n500,0.1,0.2,0.3\n", "expected at least 2 rows of wavelengths, got 1"),
    ],
)
def test_a_spectral_sensitivity_csv_that_gives_no_curve_is_one_line(tmp_path, monkeypatch, csv_text, reason):
    """A CSV whose green channel is all zero was accepted with NaN quantum efficiencies (a
    ``RuntimeWarning: divide by zero`` in the fuzz run, ``peak_qe_green: null`` in the listing);
    NaN, negative, repeated or unsorted wavelengths and a single row were accepted silently."""
    _sandbox(tmp_path, monkeypatch)
    values = SEEDS["camera with its own csv"][1]
    Path("cam.toml").write_text(toml_document(values))
    Path(CSV_NAME).write_text(csv_text)
    code, _, err, _ = _run(["--camera-file", "cam.toml", "cameras", "--json"])
    assert _one_line(code, err, "cam") == (
        f"beacon-sim: error: camera file cam.toml: sensor.ssf_csv: expected a CSV with columns wavelength_nm, r, g, b "
        f"({reason})"
    )
    Path(CSV_NAME).write_text(GOOD_CSV)
    assert _run(["--camera-file", "cam.toml", "cameras", "--json"])[0] == 0


def test_dotted_key_parts_counts_keys_not_strings_comments_or_numbers():
    from scenes.sourced import MAX_NESTING, dotted_key_parts

    text = 'a.b.c = 1.5\n"x.y.z.q.r" = "a.b.c.d.e.f.g"  # a.b.c.d.e.f.g.h\n[t . u]\nv = \'p.q.r.s.t\'\n'
    assert dotted_key_parts(text) == 3
    assert dotted_key_parts('"a"."b".c.\'d\' = 1') == 4
    assert dotted_key_parts('s = """a.b.c.d.e\n"quoted" x.y.z.w.v"""\nk = 1') == 1
    assert dotted_key_parts("[" + ".".join("k" * 17) + "]") == 17
    for folder in ("camera_models/data", "scenes/data", "studies/data", "docs/examples"):
        for path in (REPO / folder).rglob("*.toml"):
            assert dotted_key_parts(path.read_text()) <= MAX_NESTING, path


def test_the_dotted_key_scan_is_linear_on_hostile_text():
    """Quotes, comments and dots in every arrangement: each 1 MB text scanned in well under 10 s of CPU
    (~0.2 s when linear). CPU time, not wall time: a niced campaign beside a study once waited 18 s
    for a 0.15 s scan."""
    from scenes.sourced import dotted_key_parts

    n = 250_000
    for text in ('"' + '\\"' * n, '"""' * n, "'" * n, "'''" * n, "#" * n, "1." * n, '"a".' * n, "x" * 4 * n):
        start = time.process_time()
        dotted_key_parts(text)
        assert time.process_time() - start < 10, text[:12]


# -- output folders --------------------------------------------------------------------------

VICTIM_FILES = {"precious.txt": b"the user's own file\n", "results.csv": b"a,b\n1,2\n", "sub/deep.bin": b"\0" * 64}
"""The victim tree beside the working folder: what no ``--out`` may change."""

INSIDE_NAMES = [
    ".beacon-sim.lock", ".beacon-sim.json", ".write-test", "machine.csv", "results.csv", "results.parquet",
    "summary.json", "runs.json", "report.html", "index.html", "tasks", "capture.json", "image.jpg", "render.exr",
    "notes.txt",
]  # fmt: skip
"""Names an entry inside ``--out`` may have: the program's own file names and foreign ones."""

LINK_TARGETS = [
    "victim file", "victim file absolute", "victim folder", "victim sub-folder", "dangling", "self", "inside file",
    "inside folder", "/etc/passwd", "/",
]  # fmt: skip

OUT_KINDS = [
    "missing", "empty", "link to empty elsewhere", "dangling link", "link loop", "file", "fifo", "foreign",
    "other command", "same command", "unwritable", "under a file", "nested new",
]  # fmt: skip

SYSTEM = ["/", "/etc", "/usr", "/proc/self", "/sys/kernel", "/dev/shm", "/tmp", "/var", "/root", "/home"]
"""System folders: refused whatever is drawn (never written: the program refuses them first)."""

COMMANDS = {
    "study": ["study", "range-limit", "--quick"],
    "other study": ["study", "webcam-vs-dslr", "--quick"],
    "capture": ["capture"],
    "render": ["render", "--range-m", "3"],
    "main-job": ["main-job"],
    "saturation-table": ["saturation-table"],
}
"""Commands run on the drawn ``--out`` (their work functions patched)."""


@st.composite
def out_cases(draw) -> dict:
    """An ``--out`` scenario: the folder's kind, entries inside it, how it is named, the command."""
    kind = draw(st.sampled_from(OUT_KINDS))
    entries = []
    if kind in ("empty", "foreign", "other command", "same command", "unwritable", "link to empty elsewhere"):
        for _ in range(draw(st.integers(0, 4))):
            depth = draw(st.sampled_from(["", "", "tasks/", "tasks/ab/", "sub/"]))
            entries.append(
                (
                    depth + draw(st.sampled_from(INSIDE_NAMES)),
                    draw(st.sampled_from(["link", "link", "hard link", "file", "folder"])),
                    draw(st.sampled_from(LINK_TARGETS)),
                )
            )
    return {
        "kind": kind,
        "entries": entries,
        "system": draw(st.sampled_from(SYSTEM)) if draw(st.integers(0, 9)) == 0 else None,
        "spelling": draw(st.sampled_from(["d", "./d", "d/", "ABS", "x/../d", "d/."])),
        "command": draw(st.sampled_from(sorted(COMMANDS))),
        "force": draw(st.booleans()),
    }


def tree_digest(root: Path) -> dict[str, tuple]:
    """Every entry under ``root`` (links not followed): kind, mode, bytes' digest or link target."""
    out: dict[str, tuple] = {}
    for folder, dirs, files in os.walk(root, followlinks=False):
        for name in dirs + files:
            path = Path(folder) / name
            info = path.lstat()
            if stat.S_ISLNK(info.st_mode):
                out[str(path.relative_to(root))] = ("link", os.readlink(path))
            elif stat.S_ISREG(info.st_mode):
                digest = hashlib.sha256(path.read_bytes()).hexdigest()
                out[str(path.relative_to(root))] = ("file", info.st_mode, digest)
            else:
                out[str(path.relative_to(root))] = ("other", info.st_mode)
    return out


def _make_entry(out: Path, rel: str, what: str, target: str, victim: Path) -> None:
    path = out / rel
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        return  # a parent drawn as a file: that entry cannot exist
    if path.exists() or path.is_symlink():
        return
    if what == "file":
        path.write_bytes(b"foreign\n")
    elif what == "folder":
        path.mkdir()
    elif what == "hard link":
        os.link(victim / "precious.txt", path)
    else:
        relative_victim = os.path.relpath(victim, path.parent)
        path.symlink_to(
            {
                "victim file": f"{relative_victim}/precious.txt",
                "victim file absolute": str(victim / "results.csv"),
                "victim folder": relative_victim,
                "victim sub-folder": f"{relative_victim}/sub",
                "dangling": "nowhere",
                "self": path.name,
                "inside file": os.path.relpath(out / "inside.txt", path.parent),
                "inside folder": os.path.relpath(out, path.parent),
            }.get(target, target)
        )
        (out / "inside.txt").write_bytes(b"inside\n") if target == "inside file" else None


def _make_out(case: dict, home: Path, elsewhere: Path, victim: Path) -> None:
    """Build the drawn ``--out`` at ``home/d``."""
    out, kind = home / "d", case["kind"]
    if kind == "missing":
        return
    if kind == "link to empty elsewhere":
        elsewhere.mkdir()
        out.symlink_to(elsewhere)
    elif kind == "dangling link":
        out.symlink_to(home / "gone")
    elif kind == "link loop":
        out.symlink_to("d")
    elif kind in ("file", "under a file"):
        out.write_bytes(b"a file, not a folder\n")
    elif kind == "fifo":
        os.mkfifo(out)
    elif kind == "nested new":
        return
    else:
        out.mkdir()
    if kind == "foreign":
        (out / "notes.txt").write_bytes(b"the user's notes\n")
    if kind in ("other command", "same command"):
        command = COMMANDS["other study" if kind == "other command" else case["command"]]
        invoke([*command, "--out", "d"])
    for rel, what, target in case["entries"]:
        _make_entry(out.resolve(), rel, what, target, victim)
    if kind == "unwritable":
        out.chmod(0o500)


def _holds_a_link(out: Path) -> bool:
    """Whether a symbolic link stands anywhere inside the folder ``out`` (itself excepted)."""
    if not out.is_dir():
        return False
    return any(Path(f, n).is_symlink() for f, dirs, files in os.walk(out.resolve()) for n in dirs + files)


def _spelt(case: dict, home: Path) -> str:
    if case["system"]:
        return case["system"]
    if case["kind"] == "under a file":
        return "d/sub"
    if case["kind"] == "nested new":
        return "n/e/w/d"
    spelling = case["spelling"]
    return str(home / "d") if spelling == "ABS" else spelling


def test_fuzzed_out_folders_never_touch_anything_outside(tmp_path_factory):
    """Whatever ``--out`` is and holds, the victim tree beside it is unchanged and every
    refusal is one line."""
    outcomes: collections.Counter[str] = collections.Counter()
    messages: collections.Counter[str] = collections.Counter()

    @FUZZ_SETTINGS
    @given(case=out_cases())
    def check(case: dict) -> None:
        root = tmp_path_factory.mktemp("outs")
        home, victim, elsewhere = root / "cwd", root / "victim", root / "elsewhere"
        home.mkdir()
        for rel, data in VICTIM_FILES.items():
            (victim / rel).parent.mkdir(parents=True, exist_ok=True)
            (victim / rel).write_bytes(data)
        with pytest.MonkeyPatch.context() as mp:
            patch_work(mp)
            mp.chdir(home)
            _make_out(case, home, elsewhere, victim)
            before = tree_digest(victim)
            has_link = _holds_a_link(home / "d")
            args = [*COMMANDS[case["command"]], "--out", _spelt(case, home), *(["--force"] if case["force"] else [])]
            try:
                code, _out, err, _ = _run(args)
            finally:
                if (home / "d").is_dir() and not (home / "d").is_symlink():
                    (home / "d").chmod(0o700)
        outcomes[str(code)] += 1
        assert tree_digest(victim) == before, (case, args, err)
        assert code in ("work", 0, 2), (case, args, code, err[-3000:])
        if code == 2:
            line = _one_line(code, err, args)
            assert line.startswith("beacon-sim: error: out: "), (case, line)
            messages[line.split("(")[0][:60]] += 1
        if case["system"]:
            assert code == 2 and "system folder" in err, (case, err)
        if has_link and _spelt(case, home) not in ("d/sub", "n/e/w/d"):
            assert code == 2 and "symbolic link" in err, (case, "a link inside --out was accepted", err)
        shutil.rmtree(root, ignore_errors=True)

    check()
    print(f"out folders: {sum(outcomes.values())} cases, outcomes {dict(outcomes)}; refusals {dict(messages)}")
    assert outcomes["2"] > 0 and outcomes["work"] + outcomes["0"] > 0
