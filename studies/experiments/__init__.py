"""Experiments: one-off measurements built on the engine's frame path and the
runner's public API, each behind a ``beacon-sim`` command."""
