"""``python -m mocapkit`` is the ``mocapkit`` command."""

import sys

from mocapkit.cli import main

sys.exit(main())
