"""Training learned controllers: PPO, RecurrentPPO or SAC (stable-baselines3, sb3-contrib) on
the batched PersonFollow env.

- :mod:`train.ppo`: ``follow-train`` / ``python -m train``, the training script (top-down).
- :mod:`train.algos`: the learners ``--algo`` chooses from: class, rules, shipped file.
- :mod:`train.config`: hyperparameters in rl-zoo3's YAML format (``train/configs/<algo>.yaml``).
- :mod:`train.rules`: the checks of one hyperparameter value, and schedules.
- :mod:`train.wrappers`: the VecEnv wrappers between the env and the agent, and a VecEnv of
  several scenarios.
- :mod:`train.envs`: builds the agent's env for training, evaluation and inference.
- :mod:`train.run`: the run folder, atomic saves, checkpoints, the held-out evaluation log.
- :mod:`train.export`: ``--export``: copies an agent into a folder without losing a file.
- :mod:`train.report`: the learning curve, the comparison with a law, the model card.

The trained agent is used through :mod:`policies.ppo` (``make_policy("ppo")``).
"""
