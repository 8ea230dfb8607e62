"""``python -m agents.cli``: the ``marine`` command."""

import sys

from . import main

sys.exit(main())
