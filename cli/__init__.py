"""The ``petswarm`` command line."""
