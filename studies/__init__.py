"""Sweeps, metrics, maximum-range estimation, reports and the command line."""

import scenes.tool_caches  # noqa: F401  (Dr.Jit and Matplotlib caches placed before either is imported)
