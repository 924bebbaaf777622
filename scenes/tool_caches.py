"""Where the libraries the program uses keep their own caches: under the render cache's folder.

Dr.Jit keeps compiled kernels in ``$HOME/.drjit`` and Matplotlib its font list in
``~/.cache/matplotlib`` (and a config folder in ``~/.config/matplotlib``) unless told
otherwise, so a run wrote outside its ``--out`` and the cache that ``BEACON_SIM_CACHE`` moves.
:func:`place_tool_caches` points them (``DRJIT_CACHE_DIR``, read by Dr.Jit 1.x when it starts;
``MPLCONFIGDIR``, read by Matplotlib when it is imported) at ``<cache>/drjit`` and
``<cache>/matplotlib``, where ``<cache>`` is :func:`scenes.render_cache.default_cache_dir`.
It runs when the ``scenes`` package is imported, before anything imports either library
(every module that uses them imports ``scenes`` first); worker processes inherit the
variables. A variable the user set is kept.
"""

from __future__ import annotations

import os
from pathlib import Path

from scenes.render_cache import default_cache_dir

__all__ = ["TOOL_CACHES", "place_tool_caches"]

TOOL_CACHES = {"DRJIT_CACHE_DIR": "drjit", "MPLCONFIGDIR": "matplotlib"}
"""Environment variable of each library's cache folder → its sub-folder of the cache."""


def place_tool_caches(root: Path | None = None) -> dict[str, str]:
    """Set each of :data:`TOOL_CACHES` not already set to its folder under ``root`` (default
    :func:`~scenes.render_cache.default_cache_dir`); returns the variables' values. The
    folders are made when the libraries first write (a cache that cannot be written is
    reported by the command that needs it, ``check_render_cache``)."""
    base = Path(root) if root is not None else default_cache_dir()
    for variable, name in TOOL_CACHES.items():
        if not os.environ.get(variable):
            os.environ[variable] = str(base / name)
    return {variable: os.environ[variable] for variable in TOOL_CACHES}
