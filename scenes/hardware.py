"""Hardware files: which camera and beacon names exist, and which file defines each.

A camera or beacon is one TOML file whose ``name`` field is the name commands use. The
built-in ones are the package's own files (``camera_models/data/*.toml``,
``scenes/data/beacons/*.toml``); a user adds their own with :func:`add_hardware_file`
(the CLI's ``--camera-file`` / ``--beacon-file``). Names are only ever looked up in this
registry, never joined to a path, so a name such as ``../../tmp/x`` cannot reach a file.

The user's files are kept in the environment variable :data:`ENV_VAR` (``kind=path``
entries separated by ``os.pathsep``), so worker processes started by a run see the same
hardware as the command that started them.
"""

from __future__ import annotations

import hashlib
import os
import re
import tomllib
from functools import cache, lru_cache
from pathlib import Path

ENV_VAR = "BEACON_SIM_HARDWARE_FILES"
"""Environment variable holding the user's hardware files (``camera=/abs/a.toml:beacon=/abs/b.toml``)."""

PACKAGE_DIRS = {
    "camera": Path(__file__).resolve().parent.parent / "camera_models" / "data",
    "beacon": Path(__file__).resolve().parent / "data" / "beacons",
}
"""Folder of the built-in files of each kind."""

NAME_PATTERN = re.compile(r"[a-z0-9][a-z0-9._-]{0,63}")
"""What a hardware name may look like: lower-case letters, digits, '.', '_' and '-'."""


def _check_kind(kind: str) -> None:
    if kind not in PACKAGE_DIRS:
        raise ValueError(f"hardware kind: expected one of {', '.join(PACKAGE_DIRS)}, got {kind!r}")


def _file_name(path: Path) -> str:
    """The ``name`` field of a hardware file (one-line errors naming the file)."""
    try:
        mtime_ns = path.stat().st_mtime_ns
    except OSError as exc:
        raise ValueError(f"{path}: cannot read ({exc.strerror or exc})") from None
    return _name_of(path, mtime_ns)


@lru_cache(maxsize=64)
def _name_of(path: Path, _mtime_ns: int) -> str:
    """:func:`_file_name` of one version of the file (cached: names are looked up per frame)."""
    try:
        values = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ValueError(f"{path}: cannot read ({exc.strerror or exc})") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: not a TOML file ({str(exc).splitlines()[0]})") from None
    except RecursionError:
        raise ValueError(f"{path}: expected a TOML file nested a few levels deep, got one nested deeper") from None
    name = values.get("name")
    if not isinstance(name, str) or not NAME_PATTERN.fullmatch(name):
        raise ValueError(
            f"{path}: name: expected lower-case letters, digits, '.', '_' or '-' (at most 64), got {name!r}"
        )
    return name


def _user_files(kind: str) -> dict[str, Path]:
    """The user's files of ``kind`` by name (from :data:`ENV_VAR`)."""
    out: dict[str, Path] = {}
    for entry in filter(None, os.environ.get(ENV_VAR, "").split(os.pathsep)):
        k, _, path = entry.partition("=")
        if k == kind:
            out[_file_name(Path(path))] = Path(path)
    return out


@cache
def _package_files(kind: str) -> dict[str, Path]:
    """The package's own files of ``kind`` by name (fixed while the program runs)."""
    return {p.stem: p for p in sorted(PACKAGE_DIRS[kind].glob("*.toml"))}


def hardware_names(kind: str) -> list[str]:
    """Names of every ``kind`` (``camera`` or ``beacon``): built-in first, then the user's."""
    _check_kind(kind)
    return [*_package_files(kind), *(n for n in _user_files(kind) if n not in _package_files(kind))]


def hardware_file(kind: str, name: str) -> Path:
    """The file that defines the ``kind`` called ``name``; unknown names raise a one-line ValueError."""
    _check_kind(kind)
    path = _package_files(kind).get(name) or _user_files(kind).get(name)
    if path is None:
        raise ValueError(f"{kind}: expected one of {', '.join(hardware_names(kind))}, got {name!r}")
    return path


def is_builtin(kind: str, name: str) -> bool:
    """Whether ``name`` is one of the package's own files of ``kind``."""
    return name in _package_files(kind)


def add_hardware_file(kind: str, path: str | Path) -> str:
    """Make the ``kind`` defined by the file at ``path`` known by its ``name``; return the name.

    The file's own fields are checked by its loader (``scenes.view.camera_geometry`` and
    ``camera_models.camera.load_camera``, or ``scenes.beacon.beacon_design``); this only
    reads its name. A name that is already built in, or that another user file of the same
    kind defines, is an error.
    """
    _check_kind(kind)
    path = Path(path).expanduser().resolve()
    if not path.is_file():
        raise ValueError(f"{kind}-file: expected a TOML file, {path} is not a file")
    name = _file_name(path)
    if is_builtin(kind, name):
        raise ValueError(f"{path}: name: {name!r} is a built-in {kind}; give your file another name")
    other = _user_files(kind).get(name)
    if other is not None and other != path:
        raise ValueError(f"{path}: name: {name!r} is already defined by {other}")
    if other is None:
        entries = [e for e in os.environ.get(ENV_VAR, "").split(os.pathsep) if e]
        os.environ[ENV_VAR] = os.pathsep.join([*entries, f"{kind}={path}"])
    return name


def user_hardware_digest() -> str:
    """SHA-256 of the user's hardware files (names and bytes); empty when there are none.

    Part of the key of every stored study task, so editing a user file never reuses
    results computed from its old contents.
    """
    parts = [
        f"{kind}:{name}:{hashlib.sha256(path.read_bytes()).hexdigest()}"
        for kind in PACKAGE_DIRS
        for name, path in sorted(_user_files(kind).items())
    ]
    return hashlib.sha256("\n".join(parts).encode()).hexdigest() if parts else ""
