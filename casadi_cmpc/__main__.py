"""``python -m casadi_cmpc`` is the same as the ``cmpc`` command."""

import sys

from .cli import main

sys.exit(main())
