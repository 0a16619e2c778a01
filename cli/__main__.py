"""``python -m cli`` is the ``petswarm`` command (used to start child processes)."""

from cli.main import main

raise SystemExit(main())
