"""On-disk cache of renders, keyed by a content hash of everything that affects them.

Entries (format :data:`FORMAT_VERSION` 2) are single files
``<root>/v2/<key[:2]>/<key>.npz.sha`` holding the entry's key (64 hex digits), a SHA-256
of the key and the payload together (64 hex digits) and the payload (an ``.npz`` archive).
Writes go to a temporary file in the same directory, are flushed to disk and renamed into
place, so a reader sees either nothing or a complete entry. A reader recomputes the digest
and compares the stored key with the one it asked for; an entry that fails either check
(truncated, bit-flipped, or another key's entry copied over it) is deleted, reported in
one warning line and treated as a miss, so it is made again.

Format 1 entries (``<root>/<key[:2]>/<key>.npz.sha``: a digest of the payload alone, so an
entry copied over another valid one was used without a word) are still read, once: an
intact one is rewritten as a format 2 entry and removed. Its key could not be checked
(format 1 never stored it); every entry written or migrated since can.

Processes that share the cache (a study's workers) make each entry once: the one that
makes it holds an exclusive ``fcntl.flock`` on ``<key>.npz.lock`` beside the entry, and
the others wait on that lock and then read the entry (:meth:`RenderCache.get_or_make`).
"""

from __future__ import annotations

import fcntl
import hashlib
import io
import json
import logging
import os
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = [
    "ENV_CACHE_DIR",
    "FORMAT_VERSION",
    "CacheStats",
    "RenderCache",
    "atomic_write_bytes",
    "content_key",
    "default_cache_dir",
]

ENV_CACHE_DIR = "BEACON_SIM_CACHE"

FORMAT_VERSION = 2
"""Version of the entry format: 2 stores the key and a digest covering key and payload."""

_HEX = 64
"""Length of a SHA-256 in hex digits (a key and a digest)."""

log = logging.getLogger("beacon_sim")


def default_cache_dir() -> Path:
    """``$BEACON_SIM_CACHE``, else ``$XDG_CACHE_HOME/beacon-sim``, else ``~/.cache/beacon-sim``."""
    if os.environ.get(ENV_CACHE_DIR):
        return Path(os.environ[ENV_CACHE_DIR])
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "beacon-sim"


def content_key(*parts: object) -> str:
    """SHA-256 hex digest of the canonical JSON of ``parts``."""
    text = json.dumps(parts, sort_keys=True, separators=(",", ":"), default=_json_default)
    return hashlib.sha256(text.encode()).hexdigest()


def _json_default(obj: object):
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(f"not JSON-able: {type(obj).__name__}")


@dataclass
class CacheStats:
    """Counts since the cache object was made."""

    hits: int = 0
    misses: int = 0
    corrupt: int = 0
    swapped: int = 0
    migrated: int = 0
    writes: int = 0
    failed_writes: int = 0


@dataclass
class RenderCache:
    """A directory of content-addressed arrays."""

    root: Path = field(default_factory=default_cache_dir)
    stats: CacheStats = field(default_factory=CacheStats)

    def path(self, key: str) -> Path:
        """File that holds ``key`` (format :data:`FORMAT_VERSION`)."""
        return Path(self.root) / f"v{FORMAT_VERSION}" / key[:2] / f"{key}.npz.sha"

    def legacy_path(self, key: str) -> Path:
        """Where format 1 kept ``key`` (read once, then migrated)."""
        return Path(self.root) / key[:2] / f"{key}.npz.sha"

    def load(self, key: str) -> dict[str, np.ndarray] | None:
        """The arrays stored under ``key``, or ``None`` (miss, or a damaged or swapped entry removed)."""
        path = self.path(key)
        try:
            blob = path.read_bytes()
        except OSError:  # missing, or unreadable: a format 1 entry, else render again
            return self._load_legacy(key)
        stored_key, digest, payload = blob[:_HEX], blob[_HEX : 2 * _HEX], blob[2 * _HEX :]
        problem = None
        if hashlib.sha256(stored_key + payload).hexdigest().encode() != digest:
            problem = "is damaged (its digest does not match)"
        elif stored_key != key.encode():
            problem = f"holds the entry of another key ({stored_key[:12].decode(errors='replace')}…, copied over it?)"
            self.stats.swapped += 1
        arrays = None if problem else _arrays(payload)
        if arrays is None:
            self.stats.corrupt += 1
            self.stats.misses += 1
            log.warning("render cache: %s %s; making it again", path, problem or "does not hold an .npz archive")
            path.unlink(missing_ok=True)
            return None
        self.stats.hits += 1
        return arrays

    def _load_legacy(self, key: str) -> dict[str, np.ndarray] | None:
        """A format 1 entry of ``key``, rewritten in the current format; ``None`` when there is none."""
        path = self.legacy_path(key)
        try:
            blob = path.read_bytes()
        except OSError:
            self.stats.misses += 1
            return None
        digest, payload = blob[:_HEX], blob[_HEX:]
        arrays = _arrays(payload) if hashlib.sha256(payload).hexdigest().encode() == digest else None
        path.unlink(missing_ok=True)
        if arrays is None:
            self.stats.corrupt += 1
            self.stats.misses += 1
            log.warning("render cache: %s is damaged (format 1); making it again", path)
            return None
        self.stats.hits += 1
        self.stats.migrated += 1
        self._write(key, payload)
        return arrays

    def get_or_make(self, key: str, make: Callable[[], dict[str, np.ndarray]]) -> tuple[dict[str, np.ndarray], bool]:
        """The arrays stored under ``key``, or ``make()``'s, stored; and whether they came
        from the cache. While one process makes an entry, others asking for the same key
        wait for it instead of making it again (two workers reaching a new diffuser
        configuration together had both rendered its near field)."""
        stored = self.load(key)
        if stored is not None:
            return stored, True
        with self._making(key):
            stored = self.load(key)  # made by another process while this one waited
            if stored is not None:
                return stored, True
            arrays = make()
            self.store(key, arrays)
        return arrays, False

    @contextmanager
    def _making(self, key: str) -> Iterator[None]:
        """Hold the exclusive lock on ``key``'s entry (none where the cache cannot be written)."""
        path = self.path(key).with_suffix(".lock")
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(path, os.O_CREAT | os.O_RDWR, 0o644)
        except OSError:
            fd = None
        try:
            if fd is not None:
                fcntl.flock(fd, fcntl.LOCK_EX)
            yield
        finally:
            if fd is not None:
                os.close(fd)  # closing the only descriptor releases the lock

    def store(self, key: str, arrays: dict[str, np.ndarray]) -> Path | None:
        """Store ``arrays`` under ``key`` atomically; returns the entry's path, or ``None`` when
        the cache cannot be written (unwritable folder, full disk): the render in hand is still
        good, so that is a warning, never an error that would throw the finished work away."""
        buf = io.BytesIO()
        np.savez_compressed(buf, **arrays)
        return self._write(key, buf.getvalue())

    def _write(self, key: str, payload: bytes) -> Path | None:
        """Write ``payload`` as the format 2 entry of ``key`` (see :meth:`store`)."""
        path = self.path(key)
        stored_key = key.encode()
        if len(stored_key) != _HEX:
            raise ValueError(f"key: expected a SHA-256 in {_HEX} hex digits, got {key!r}")
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            atomic_write_bytes(path, stored_key + hashlib.sha256(stored_key + payload).hexdigest().encode() + payload)
        except OSError as exc:
            self.stats.failed_writes += 1
            log.warning("render cache: cannot write %s (%s); continuing without storing it", path, exc.strerror or exc)
            return None
        self.stats.writes += 1
        return path


def _arrays(payload: bytes) -> dict[str, np.ndarray] | None:
    """The arrays of an ``.npz`` payload, or ``None`` when it is not one."""
    try:
        with np.load(io.BytesIO(payload), allow_pickle=False) as npz:
            return {k: npz[k] for k in npz.files}
    except (ValueError, OSError, EOFError, KeyError):
        return None


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` so that readers never see a partial file."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        umask = os.umask(0)
        os.umask(umask)
        os.fchmod(fd, 0o666 & ~umask)  # mkstemp makes 0600; give the file normal permissions
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except OSError as exc:
        Path(tmp).unlink(missing_ok=True)
        if exc.filename is None:  # a failed write or fsync names no file: name the one being written
            raise OSError(exc.errno, exc.strerror, str(path)) from exc
        raise
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
