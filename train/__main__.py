"""``python -m train``: the same as ``follow-train`` (:mod:`train.ppo`)."""

import sys

from train.ppo import main

sys.exit(main())
