"""Learned controllers: the agent's own feature pipeline, its network and its loading.

:mod:`.features` is numpy only: how an agent sees the env (extra observation features, frame
stacking, action scaling and increments), batched over lanes. Training wraps the very same code
as stable-baselines3 ``VecEnvWrapper`` s (:mod:`train.wrappers`), so a trained agent sees at
inference exactly what it saw in training. :mod:`.ppo` loads an agent (torch and
stable-baselines3, imported only when an agent is built) and acts through that pipeline;
:mod:`.networks` rebuilds its network per algorithm (PPO, SAC, RecurrentPPO with its LSTM
state). :mod:`.ensemble` acts with the mean of several agents' actions (a training study's
seeds, through its ``ensemble.yaml``).
"""
