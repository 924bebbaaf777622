"""What a camera does to light: lens, sensor, image processing and exposure control."""

import scenes.tool_caches  # noqa: F401  (Dr.Jit and Matplotlib caches placed before either is imported)
