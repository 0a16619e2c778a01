"""``python -m cli`` is the ``petswarm`` command (used to start child processes)."""

import sys

from cli.lean import leave_out_openssl

leave_out_openssl(sys.argv[1:])  # before cli.main imports asyncio

from cli.main import main  # noqa: E402

raise SystemExit(main())
