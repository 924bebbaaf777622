"""``python -m studies.cli``: the same command line as ``beacon-sim``."""

from studies.cli.app import main

__all__ = []

main()
