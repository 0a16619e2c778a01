"""The ``petswarm`` command line."""

import petswarm  # noqa: F401  (numpy's float paths pinned before numpy loads: radio_hub.determinism)
