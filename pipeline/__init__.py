"""What the robot runs: trackers, angles, range, attitude, frames, messages, calibration.

Entry points: :func:`pipeline.detect.detect` (image → side, markers, pose, global pose),
:func:`pipeline.evaluate.evaluate_detection` (scored against ground truth),
:func:`pipeline.crlb.pose_crlb` (Cramér–Rao bound). Conventions: ``pipeline/CONVENTIONS.md``.
"""

import scenes.tool_caches  # noqa: F401  (Dr.Jit and Matplotlib caches placed before either is imported)
