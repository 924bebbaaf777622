"""On-disk cache of renders, keyed by a content hash of everything that affects them.

Entries are single files ``<root>/<key[:2]>/<key>.npz.sha`` holding a 64-byte hex
SHA-256 of the payload followed by the payload (an ``.npz`` archive). Writes go to a
temporary file in the same directory, are flushed to disk and renamed into place, so a
reader sees either nothing or a complete entry. A reader recomputes the digest; an
entry that fails the check (truncated, bit-flipped) is deleted and reported as a miss.

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

ENV_CACHE_DIR = "BEACON_SIM_CACHE"

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
    writes: int = 0
    failed_writes: int = 0


@dataclass
class RenderCache:
    """A directory of content-addressed arrays."""

    root: Path = field(default_factory=default_cache_dir)
    stats: CacheStats = field(default_factory=CacheStats)

    def path(self, key: str) -> Path:
        """File that holds ``key``."""
        return Path(self.root) / key[:2] / f"{key}.npz.sha"

    def load(self, key: str) -> dict[str, np.ndarray] | None:
        """The arrays stored under ``key``, or ``None`` (miss, or corrupt entry removed)."""
        path = self.path(key)
        try:
            blob = path.read_bytes()
        except OSError:  # missing, or unreadable: render again
            self.stats.misses += 1
            return None
        digest, payload = blob[:64], blob[64:]
        try:
            if hashlib.sha256(payload).hexdigest().encode() != digest:
                raise ValueError("digest mismatch")
            with np.load(io.BytesIO(payload), allow_pickle=False) as npz:
                arrays = {k: npz[k] for k in npz.files}
        except (ValueError, OSError, EOFError, KeyError):
            self.stats.corrupt += 1
            self.stats.misses += 1
            path.unlink(missing_ok=True)
            return None
        self.stats.hits += 1
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
        payload = buf.getvalue()
        path = self.path(key)
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            atomic_write_bytes(path, hashlib.sha256(payload).hexdigest().encode() + payload)
        except OSError as exc:
            self.stats.failed_writes += 1
            log.warning("render cache: cannot write %s (%s); continuing without storing it", path, exc.strerror or exc)
            return None
        self.stats.writes += 1
        return path


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
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
