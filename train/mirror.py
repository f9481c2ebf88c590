"""The mirror-symmetric policy, under the name training configs and saved models use.

The class lives with the agent (:mod:`policies.learned.mirror`), so that loading an agent needs
no training code; ``train.mirror.MirrorMlpPolicy`` stays importable for the hyperparameter files
and for models that name it.
"""

from policies.learned.mirror import MirrorMlpPolicy

__all__ = ["MirrorMlpPolicy"]
