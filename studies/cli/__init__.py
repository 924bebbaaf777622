"""The ``beacon-sim`` command line (:mod:`studies.cli.app` assembles it)."""
