"""A trained agent's network for inference, per algorithm: PPO's, SAC's, RecurrentPPO's.

:func:`load_network` rebuilds the policy network saved in a stable-baselines3 (or sb3-contrib)
``.zip`` without the algorithm (no optimizer, no rollout or replay buffer) and acts with it
deterministically, as the library's ``predict`` does:

- PPO: the mean of the Gaussian, clipped to the action box;
- SAC: the squashed mean, ``tanh(mean)``, rescaled from ``[-1, 1]`` onto the action box
  (``unscale_action``), not clipped;
- RecurrentPPO: the mean of the Gaussian after the actor's LSTM, clipped; the LSTM's hidden
  and cell state are kept per lane in a :class:`Memory`, which a new episode starts at zero
  (the episode-start flag of the first step, as sb3-contrib's ``predict`` is given it).

Every network runs one lane (one row) at a time, so a batch gives each lane exactly the action
it gets alone (:mod:`policies.learned.ppo` says why). torch and SB3 are imported only here,
when a network is loaded.

A network acts in float64 (its float32 weights widened once, when it is loaded) and its action
is rounded to float32 at the end: so an agent acts the same on every CPU. In float32, torch's
matrix products pick their kernels by CPU (AVX-512, AVX2, ...) and round differently in the
last bit, and 30 s of closed loop carry such a bit into another episode: the shipped agent's
evaluation depended on the machine. In float64 the kernels still differ, by about 1e-16, far
below float32's rounding step (6e-8 relative), so the float32 action they round to is the same
but for a chance of about 1e-7 per action, measured on the observations of real episodes (an
output near zero, the turn rate on a straight walk, rounds apart most often): about one episode
in ten thousand can still end differently on another CPU, where in float32 most did
(``tests/policies/learned/test_networks_any_cpu.py`` runs agents under other instruction sets
and compares). The action is within float32 rounding of the library's float32 ``predict``, not
equal to it bit for bit. Observations are rounded to float32 first, as the library's path
takes them.
"""

from __future__ import annotations

from copy import deepcopy
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["ALGOS", "Memory", "Network", "RecurrentNetwork", "load_network", "widened"]

#: The algorithms ``follow-train --algo`` trains (``config.yaml``'s ``algo``; none: PPO).
ALGOS = ("ppo", "recurrent_ppo", "sac")
_LIBRARY = {"ppo": "stable-baselines3 PPO", "recurrent_ppo": "sb3-contrib RecurrentPPO",
            "sac": "stable-baselines3 SAC"}  # fmt: skip


class _NoOptimizer:
    """Stands in for the training optimizer when a policy network is built for inference."""

    def __init__(self, params: Any, lr: float = 0.0, **kwargs: Any) -> None:
        pass


class Memory:
    """What a recurrent network remembers of ``n`` lanes' episodes: each lane's LSTM state
    ``(hidden, cell)`` (torch tensors, ``(layers, 1, units)``), and whether its next step
    starts an episode."""

    def __init__(self, n: int, shape: tuple[int, ...]) -> None:
        import torch

        zeros = torch.zeros(shape, dtype=torch.float64)
        self.states: list[tuple[Any, Any]] = [(zeros, zeros) for _ in range(n)]
        self.starts = np.ones(n, dtype=bool)

    def restart(self, lanes: np.ndarray) -> None:
        """Start the flagged ``lanes`` (bool per lane) afresh: their state zero, their next
        step an episode's first (SB3's ``episode_starts``)."""
        for i in np.flatnonzero(lanes):
            hidden, cell = self.states[i]
            self.states[i] = (hidden * 0, cell * 0)
        self.starts[lanes] = True


class Network:
    """A loaded feed-forward policy network (PPO's or SAC's), acting deterministically on agent
    observations one row at a time, in float64 (module docstring).

    :param policy: the SB3 policy; a float64 copy of it acts (:func:`widened`), and the
        caller's goes on as it was.
    :param owned: the policy is the network's alone (:func:`load_network` built it): widened
        in place, with no copy.
    """

    def __init__(self, policy: Any, *, owned: bool = False) -> None:
        # Widened before anything below takes its layers (the mean path keeps references).
        self.policy = policy = widened(policy, copy=not owned)
        policy.set_training_mode(False)
        self.observation_space = policy.observation_space
        self.action_space = policy.action_space
        self._low, self._high = self.action_space.low, self.action_space.high
        self._shape = self.action_space.shape
        self._squashed = bool(getattr(policy, "squash_output", False))
        self._gaussian = _gaussian_mean(policy)

    def memory(self, n: int) -> Memory | None:
        """A fresh memory for ``n`` lanes (a feed-forward network has none)."""
        return None

    def _output(self, action: Any) -> np.ndarray:
        """One row's network output as the library's ``predict`` returns it."""
        action = action.cpu().numpy().reshape((-1, *self._shape))
        if self._squashed:  # SAC: tanh output in [-1, 1], rescaled onto the box
            return self.policy.unscale_action(action)[0]
        return np.clip(action, self._low, self._high)[0]

    def act(self, obs: np.ndarray, memory: Memory | None = None) -> np.ndarray:
        """Actions ``(n, m)`` float32 for agent observations ``(n, k)``, computed in float64."""
        import torch

        out = np.empty((len(obs), *self._shape), dtype=np.float32)
        # float32 first, as SB3's preprocessing rounds them on its own paths, then widened
        rows = torch.from_numpy(np.asarray(obs, dtype=np.float32).astype(np.float64))
        with torch.inference_mode():
            if self._gaussian is not None:  # PPO: the mean, without building a distribution
                for i in range(len(obs)):
                    out[i] = self._gaussian(rows[i : i + 1]).numpy().reshape(self._shape)
                return np.clip(out, self._low, self._high)
            for i in range(len(obs)):
                out[i] = self._output(self.policy._predict(rows[i : i + 1], deterministic=True))
        return out


class RecurrentNetwork(Network):
    """A loaded RecurrentPPO policy: the actor's LSTM state is carried per lane in a
    :class:`Memory` from one step to the next."""

    def memory(self, n: int) -> Memory:
        """Zero LSTM states for ``n`` lanes, each about to start an episode."""
        return Memory(n, tuple(self.policy.lstm_hidden_state_shape))

    def act(self, obs: np.ndarray, memory: Memory | None = None) -> np.ndarray:
        """Actions ``(n, m)`` for agent observations ``(n, k)``, advancing ``memory``.

        :raises ValueError: without a memory of ``n`` lanes.
        """
        import torch

        if memory is None or len(memory.states) != len(obs):
            raise ValueError(f"a recurrent network needs a memory of {len(obs)} lanes")
        out = np.empty((len(obs), *self._shape), dtype=np.float32)
        with torch.no_grad():
            for i in range(len(obs)):
                tensor = torch.as_tensor(np.asarray(obs[i : i + 1], dtype=np.float32))
                start = torch.tensor([float(memory.starts[i])], dtype=torch.float64)
                action, state = self.policy._predict(
                    tensor, lstm_states=memory.states[i], episode_starts=start, deterministic=True
                )
                memory.states[i] = (state[0], state[1])
                out[i] = self._output(action)
        memory.starts[:] = False
        return out


def widened(policy: Any, *, copy: bool = True) -> Any:
    """``policy`` in float64: its parameters and buffers, and what its features extractors are
    given (SB3's ``preprocess_obs`` turns a Box's observation into float32 on the way in,
    ``obs.float()``; the float32 values widen exactly).

    :param copy: widen a copy and leave ``policy`` as it was, so that a caller's model goes on
        predicting in float32 through the library's own paths (sb3-contrib's recurrent
        ``predict`` builds float32 LSTM states, which a float64 LSTM refuses); False: widen
        ``policy`` itself.
    :raises ValueError: if ``policy`` cannot be copied (torch copies no tensor computed from
        others, such as the exploration matrix of a policy trained with ``use_sde``).
    """
    import torch
    from stable_baselines3.common.torch_layers import BaseFeaturesExtractor

    def widen(value: Any) -> Any:
        if isinstance(value, torch.Tensor) and value.is_floating_point():
            return value.to(torch.float64)
        if isinstance(value, dict):
            return {key: widen(item) for key, item in value.items()}
        return value

    if copy:
        try:
            policy = deepcopy(policy)
        except RuntimeError as e:
            raise ValueError(
                f"cannot copy this {type(policy).__name__} to act in float64 ({e}); "
                "Network(policy, owned=True) widens the policy itself"
            ) from None
    policy.to(torch.float64)
    for module in policy.modules():
        if isinstance(module, BaseFeaturesExtractor):
            module.register_forward_pre_hook(lambda _, args: tuple(map(widen, args)))
    return policy


def _gaussian_mean(policy: Any) -> Any:
    """For an actor-critic policy with a Gaussian over its actions (PPO's), a function of one
    observation row giving the Gaussian's mean: the library's deterministic action, computed by
    the same operations in the same order as its ``get_distribution`` (so bitwise the same,
    tested), without the distribution object it builds only to return that mean and with the
    layers called as functions (:func:`_function_of`): 3.4 times the rows per second of the
    library's path (``bench.agents``). None for any other policy (a recurrent one, or one that
    acts in its own way), which acts through the library's ``_predict``."""
    from stable_baselines3.common.distributions import DiagGaussianDistribution
    from stable_baselines3.common.policies import ActorCriticPolicy, BaseModel

    kind = type(policy)
    library = all(
        getattr(kind, method, None) is getattr(ActorCriticPolicy, method)
        for method in ("_predict", "get_distribution", "_get_action_dist_from_latent")
    )
    if not (library and type(policy.action_dist) is DiagGaussianDistribution):
        return None

    actor, head = _actor_of(policy.mlp_extractor), _function_of(policy.action_net)
    if _flat_box(policy):  # a float32 row (1, k) is its own features: float() and flatten(1)
        return lambda row: head(actor(row))  # each give the same tensor back

    def mean(row: Any) -> Any:
        return head(actor(BaseModel.extract_features(policy, row, policy.pi_features_extractor)))

    return mean


def _flat_box(policy: Any) -> bool:
    """Whether ``policy`` reads a flat ``Box`` that is not an image through SB3's
    ``FlattenExtractor``, so that its features of a float32 row are the row."""
    from gymnasium import spaces
    from stable_baselines3.common.preprocessing import is_image_space
    from stable_baselines3.common.torch_layers import FlattenExtractor

    space = policy.observation_space
    return (
        type(policy.pi_features_extractor) is FlattenExtractor
        and isinstance(space, spaces.Box)
        and len(space.shape) == 1
        and not is_image_space(space)
    )


def _function_of(module: Any) -> Any:
    """``module``'s forward as direct torch calls where it is a plain layer (SB3's MLPs:
    ``Sequential``, ``Linear``, ``Tanh``, ``ReLU``) or offers its own (``functional``, the mirror
    policy's head): each module call costs more in Python than a 64-unit layer's arithmetic on
    one row. The same operations in the same order, so the same bits; any other module as it is.
    """
    import torch
    from torch import nn
    from torch.nn import functional

    kind = type(module)
    if hasattr(module, "functional"):
        return module.functional(_function_of)
    if kind is nn.Sequential:
        layers = [_function_of(layer) for layer in module]

        def chain(x: Any) -> Any:
            for layer in layers:
                x = layer(x)
            return x

        return chain
    if kind is nn.Linear:
        weight, bias = module.weight, module.bias
        return lambda x: functional.linear(x, weight, bias)
    if kind is nn.Tanh:
        return torch.tanh
    if kind is nn.ReLU and not module.inplace:
        return torch.relu
    return module


def _actor_of(extractor: Any) -> Any:
    """An MLP extractor's ``forward_actor`` as :func:`_function_of` gives layers: SB3's
    ``MlpExtractor`` is its actor network; an extractor may offer its own
    (``functional_actor``, the mirror policy's); any other as it is."""
    from stable_baselines3.common.torch_layers import MlpExtractor

    if hasattr(extractor, "functional_actor"):
        return extractor.functional_actor(_actor_of, _function_of)
    if type(extractor) is MlpExtractor:
        return _function_of(extractor.policy_net)
    return extractor.forward_actor


def load_network(path: Path, algo: str, policy: Any, error: type[Exception]) -> Network:
    """The policy network saved in the model ``path`` of algorithm ``algo``.

    :param policy: the configuration's ``policy`` (a dotted ``MirrorMlpPolicy`` is loaded from
        :mod:`policies.learned.mirror`, not from where training imported it).
    :param error: the exception to raise, naming ``path``, if the file is not such a model.
    """
    from stable_baselines3.common.save_util import load_from_zip_file

    custom: dict[str, Any] = {}
    if isinstance(policy, str) and policy.endswith("MirrorMlpPolicy"):
        from policies.learned.mirror import MirrorMlpPolicy

        # The saved model names the class where training imported it; loading it from here
        # keeps training code out of inference.
        custom["policy_class"] = MirrorMlpPolicy
    try:
        data, params, _ = load_from_zip_file(path, device="cpu", custom_objects=custom)
    except Exception as e:  # zipfile, pickle, torch and SB3 each raise their own
        raise error(
            f"{path}: not a readable {_LIBRARY[algo]} model ({type(e).__name__}: {e})"
        ) from None
    if data is None or not params or "policy" not in params:
        # SB3 returns None for members a zip lacks rather than raising
        raise error(
            f"{path}: not a {_LIBRARY[algo]} model: the zip lacks its 'data' or 'policy.pth' member"
        )
    try:
        kwargs = dict(data.get("policy_kwargs") or {})
        # Inference needs no optimizer (and building torch's Adam imports its compiler,
        # about a second).
        kwargs["optimizer_class"] = _NoOptimizer
        # SAC keeps use_sde in its policy_kwargs, PPO beside them.
        kwargs.setdefault("use_sde", data.get("use_sde", False))
        net = data["policy_class"](
            data["observation_space"], data["action_space"], lambda _: 0.0, **kwargs
        )
        net.load_state_dict(params["policy"])
    except Exception as e:  # zipfile, pickle, torch and SB3 each raise their own
        raise error(
            f"{path}: not a readable {_LIBRARY[algo]} model ({type(e).__name__}: {e})"
        ) from None
    recurrent = hasattr(net, "lstm_hidden_state_shape")
    if recurrent != (algo == "recurrent_ppo"):
        kind = "a recurrent" if recurrent else "a feed-forward"
        raise error(f"{path}: holds {kind} policy ({type(net).__name__}), not {_LIBRARY[algo]}'s")
    # The policy was built here for the network alone: widened in place, not copied (a
    # use_sde policy holds a tensor torch will not copy).
    return RecurrentNetwork(net, owned=True) if recurrent else Network(net, owned=True)
