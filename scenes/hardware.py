"""Hardware files: which camera and beacon names exist, and the contents that define each.

A camera or beacon is one TOML file whose ``name`` field is the name commands use. The
built-in ones are the package's own files (``camera_models/data/*.toml``,
``scenes/data/beacons/*.toml``); a user adds their own with :func:`add_hardware_file`
(the CLI's ``--camera-file`` / ``--beacon-file``). Names are only ever looked up in this
registry, never joined to a path, so a name such as ``../../tmp/x`` cannot reach a file.

A user's file is read **once**, when it is added, together with every file it names
(:data:`REFERENCES`: a camera's ``body`` and its spectral-sensitivity CSV ``ssf_csv``);
from then on the program uses those contents (:class:`HardwareFile`), never the paths. A
run hands the same contents to its workers (:func:`user_hardware` in the parent,
:func:`install_hardware` in each local process or Dask worker) and keys its stored
results by their digest (:attr:`HardwareSet.digest`), so a file edited, removed or
unreachable while a run goes on changes neither what the workers compute nor the key it
is stored under.
"""

from __future__ import annotations

import hashlib
import re
import tomllib
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path

from scenes.sourced import check_dotted_keys

__all__ = [
    "MAX_FILE_BYTES",
    "NAME_PATTERN",
    "PACKAGE_DIRS",
    "REFERENCES",
    "HardwareFile",
    "HardwareSet",
    "NamedFile",
    "Reference",
    "add_hardware_file",
    "clear_user_hardware",
    "hardware_file",
    "hardware_names",
    "hardware_source",
    "install_hardware",
    "is_builtin",
    "user_hardware",
    "user_hardware_digest",
]

_CAMERA_DIR = Path(__file__).resolve().parent.parent / "camera_models" / "data"

PACKAGE_DIRS = {
    "camera": _CAMERA_DIR,
    "beacon": Path(__file__).resolve().parent / "data" / "beacons",
}
"""Folder of the built-in files of each kind."""

NAME_PATTERN = re.compile(r"[a-z0-9][a-z0-9._-]{0,63}")
"""What a hardware name may look like: lower-case letters, digits, '.', '_' and '-'."""

MAX_FILE_BYTES = 1 << 20
"""Largest hardware file, or file it names, that is read (1 MiB). The largest built-in file is
about 20 kB and a spectral-sensitivity CSV about 2 kB; the limit leaves room for fifty times
that while a mistaken path (an image, a log, a device) fails at once instead of being read."""


@dataclass(frozen=True)
class Reference:
    """A field of a hardware file that names another file.

    Attributes
    ----------
    field
        Dotted path of the field (``body``, ``sensor.ssf_csv``).
    package_dir
        Folder of the built-in files it may name.
    suffix
        Added to the field's value to make the built-in file's name (``.toml`` for a body).
    beside
        Whether it may also name a file next to the hardware file (a user's own CSV).
    nested
        Whether the named file is itself TOML whose fields may name files (a body names its CSV).
    """

    field: str
    package_dir: Path
    suffix: str = ""
    beside: bool = False
    nested: bool = False


REFERENCES: dict[str, tuple[Reference, ...]] = {
    "camera": (
        Reference("body", _CAMERA_DIR / "bodies", suffix=".toml", nested=True),
        Reference("sensor.ssf_csv", _CAMERA_DIR / "ssf", beside=True),
    ),
    "beacon": (),
}
"""The fields of each kind of hardware file that name other files (read with the file). A
value is a plain file name, never a path: a built-in file, or (``beside``) one in the
hardware file's own folder."""


@dataclass(frozen=True)
class NamedFile:
    """A file that a hardware file names, as it was read.

    Attributes
    ----------
    field
        The dotted field that names it (``body``, ``sensor.ssf_csv``).
    value
        What the field says (``canon-eos-1300d``, ``mine.csv``).
    data
        The file's bytes.
    """

    field: str
    value: str
    data: bytes


@dataclass(frozen=True)
class HardwareFile:
    """One camera or beacon file and the files it names, as read once.

    Attributes
    ----------
    kind, name
        ``camera`` or ``beacon``, and the file's ``name`` field.
    label
        How messages name the file (its file name).
    data
        The file's bytes (UTF-8 TOML).
    named
        The files it names (:data:`REFERENCES`) that exist, as read with it.
    builtin
        Whether it is one of the package's own files.
    origin
        Where it was read from (for messages; not part of :attr:`digest`).
    """

    kind: str
    name: str
    label: str
    data: bytes
    named: tuple[NamedFile, ...] = ()
    builtin: bool = False
    origin: str = field(default="", compare=False)

    @property
    def text(self) -> str:
        """The file's text."""
        return self.data.decode("utf-8")

    def named_file(self, field_: str, value: str) -> bytes | None:
        """The bytes of the file that ``field_ = value`` names, or None when it names none."""
        return next((f.data for f in self.named if f.field == field_ and f.value == value), None)

    @property
    def digest(self) -> str:
        """SHA-256 of the kind, name and bytes of the file and of every file it names."""
        parts = [self.kind, self.name, _sha(self.data)]
        parts += [f"{f.field}={f.value}:{_sha(f.data)}" for f in self.named]
        return _sha("\n".join(parts).encode())


@dataclass(frozen=True)
class HardwareSet:
    """The user's hardware files as one value: what a run hands its workers and keys by."""

    files: tuple[HardwareFile, ...] = ()

    @property
    def digest(self) -> str:
        """SHA-256 over the files' digests; empty when there are none (built-in hardware only)."""
        parts = sorted(f"{f.kind}:{f.name}:{f.digest}" for f in self.files)
        return _sha("\n".join(parts).encode()) if parts else ""


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


_USER: dict[tuple[str, str], HardwareFile] = {}
"""The user's files in this process by (kind, name), in the order they were added."""


def _check_kind(kind: str) -> None:
    if kind not in PACKAGE_DIRS:
        raise ValueError(f"hardware kind: expected one of {', '.join(PACKAGE_DIRS)}, got {kind!r}")


def _read(path: Path, what: str) -> bytes:
    """A file's bytes, at most :data:`MAX_FILE_BYTES` (one-line errors naming ``what``)."""
    try:
        size = path.stat().st_size
        if size > MAX_FILE_BYTES:
            raise ValueError(f"{what}: expected a file of at most {MAX_FILE_BYTES} bytes, got {size} bytes")
        return path.read_bytes()
    except OSError as exc:
        raise ValueError(f"{what}: cannot read ({exc.strerror or exc})") from None


def _toml(data: bytes, what: str) -> dict:
    """Parsed TOML (one-line errors naming ``what``); a dotted key too long to parse in bounded
    time and memory is refused first (:func:`scenes.sourced.check_dotted_keys`)."""
    try:
        text = data.decode("utf-8")
        check_dotted_keys(text, what)
        return tomllib.loads(text)
    except UnicodeDecodeError:
        raise ValueError(f"{what}: not a TOML file (not UTF-8 text)") from None
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{what}: not a TOML file ({str(exc).splitlines()[0]})") from None
    except RecursionError:
        raise ValueError(f"{what}: not a TOML file (nested too deeply)") from None


def _plain_name(value: str) -> bool:
    """Whether ``value`` is a file name without any folder part."""
    return bool(value) and value not in (".", "..") and "/" not in value and "\\" not in value and "\0" not in value


def _field(values: dict, dotted: str) -> object:
    node: object = values
    for key in dotted.split("."):
        if not isinstance(node, dict):
            return None
        node = node.get(key)
    return node


def _named_files(kind: str, values: dict, folder: Path, label: str) -> tuple[NamedFile, ...]:
    """Read every file that a ``kind`` file's ``values`` name (those that exist; the loaders
    report the rest field by field)."""
    documents, out = [values], []
    for ref in REFERENCES[kind]:
        for document in tuple(documents):
            value = _field(document, ref.field)
            if not isinstance(value, str) or not _plain_name(value):
                continue
            candidates = [ref.package_dir / f"{value}{ref.suffix}"] + ([folder / value] if ref.beside else [])
            path = next((p for p in candidates if p.is_file()), None)
            if path is None or any(f.field == ref.field and f.value == value for f in out):
                continue
            data = _read(path, f"{label}: {ref.field}")
            out.append(NamedFile(ref.field, value, data))
            if ref.nested:
                documents.append(_toml(data, f"{label}: {ref.field} {path.name}"))
    return tuple(out)


def _load(kind: str, path: Path, builtin: bool) -> HardwareFile:
    """Read the ``kind`` file at ``path`` and the files it names, once."""
    data = _read(path, str(path))
    values = _toml(data, str(path))
    name = values.get("name")
    if not isinstance(name, str) or not NAME_PATTERN.fullmatch(name):
        raise ValueError(
            f"{path}: name: expected lower-case letters, digits, '.', '_' or '-' (at most 64), got {name!r}"
        )
    named = _named_files(kind, values, path.parent, path.name)
    return HardwareFile(kind, name, path.name, data, named, builtin, str(path))


@cache
def _package_paths(kind: str) -> dict[str, Path]:
    """The package's own files of ``kind`` by name (fixed while the program runs)."""
    return {p.stem: p for p in sorted(PACKAGE_DIRS[kind].glob("*.toml"))}


@cache
def _package_file(kind: str, name: str) -> HardwareFile:
    """A built-in file and the files it names, read once per process."""
    return _load(kind, _package_paths(kind)[name], builtin=True)


def _user_names(kind: str) -> list[str]:
    return [n for k, n in _USER if k == kind]


def hardware_names(kind: str) -> list[str]:
    """Names of every ``kind`` (``camera`` or ``beacon``): built-in first, then the user's."""
    _check_kind(kind)
    return [*_package_paths(kind), *_user_names(kind)]


def hardware_source(kind: str, name: str) -> HardwareFile:
    """The contents that define the ``kind`` called ``name``; unknown names raise a one-line ValueError."""
    _check_kind(kind)
    if name in _package_paths(kind):
        return _package_file(kind, name)
    found = _USER.get((kind, name)) if isinstance(name, str) else None
    if found is None:
        raise ValueError(f"{kind}: expected one of {', '.join(hardware_names(kind))}, got {name!r}")
    return found


def hardware_file(kind: str, name: str) -> Path:
    """The path the ``kind`` called ``name`` was read from (a built-in's package file)."""
    return Path(hardware_source(kind, name).origin)


def is_builtin(kind: str, name: str) -> bool:
    """Whether ``name`` is one of the package's own files of ``kind``."""
    return name in _package_paths(kind)


def add_hardware_file(kind: str, path: str | Path) -> str:
    """Read the ``kind`` file at ``path`` (and every file it names) and make it known by its
    ``name``; return the name.

    The file's own fields are checked by its loader (``camera_models.camera.load_camera``,
    ``scenes.beacon.beacon_design``); this reads the bytes once and its name. A name that is
    built in, or that a user file from another path defines, is an error; the same path again
    is read again (a new command sees the file's new contents).
    """
    _check_kind(kind)
    try:
        path = Path(path).expanduser().resolve()
    except RuntimeError:  # ~user with no such user, or (Python 3.11) a loop of symbolic links
        why = "no such user's home folder" if str(path).startswith("~") else "a loop of symbolic links"
        raise ValueError(f"{kind}-file: expected a TOML file, got {path} ({why})") from None
    if not path.is_file():
        raise ValueError(f"{kind}-file: expected a TOML file, {path} is not a file")
    loaded = _load(kind, path, builtin=False)
    if is_builtin(kind, loaded.name):
        raise ValueError(f"{path}: name: {loaded.name!r} is a built-in {kind}; give your file another name")
    other = _USER.get((kind, loaded.name))
    if other is not None and other.origin != loaded.origin:
        raise ValueError(f"{path}: name: {loaded.name!r} is already defined by {other.origin}")
    _USER[(kind, loaded.name)] = loaded
    return loaded.name


def user_hardware() -> HardwareSet:
    """The user's hardware files in this process, as one value to hand to workers."""
    return HardwareSet(tuple(_USER.values()))


def install_hardware(hardware: HardwareSet) -> None:
    """Make ``hardware`` this process's user files (a worker, before its tasks), replacing any others."""
    _USER.clear()
    for f in hardware.files:
        _check_kind(f.kind)
        _USER[(f.kind, f.name)] = f


def clear_user_hardware() -> None:
    """Forget the user's files (built-in hardware only)."""
    _USER.clear()


def user_hardware_digest() -> str:
    """SHA-256 of the user's hardware files and every file they name; empty when there are none.

    Part of the key of every stored study task, so results computed from other contents of a
    user file are never reused.
    """
    return user_hardware().digest
