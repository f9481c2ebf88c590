"""``python -m bridge``: the same as ``follow-robot``."""

import sys

from bridge.cli import main

sys.exit(main())
