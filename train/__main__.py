"""``python -m train``: the same as ``follow-train`` (:mod:`train.cli`)."""

import sys

from train.cli import main

sys.exit(main())
