"""``python -m wise``: the ``wise`` command."""

import sys

from wise.cli import main

sys.exit(main())
