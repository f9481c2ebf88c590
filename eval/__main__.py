"""``python -m eval``: the same as the ``follow-eval`` command (see :mod:`eval.cli`)."""

import sys

from eval.cli import main

sys.exit(main())
