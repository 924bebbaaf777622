"""The study engine: frame tasks, the one frame path (render → capture → score),
the runner, sweeps, scoring, metrics, maximum range, tables and reports."""
