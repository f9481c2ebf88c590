"""A mirror-symmetric actor-critic: the agent turns left exactly as it turns right.

The task is symmetric under a left-right reflection: mirror the world, and the person's offset,
the yaw rate and the turn command change sign while distances and speeds do not. An MLP learns
that only approximately, and a small bias around zero offset is enough to turn towards the wrong
side when the person is nearly centred. :class:`MirrorMlpPolicy` builds the symmetry in: with
``M`` flipping the signs of the mirrored observation entries and ``S`` those of the action,

    mean(x)  = (f(x) + S f(M x)) / 2        so  mean(M x) = S mean(x)
    value(x) = (g(x) + g(M x)) / 2          so  value(M x) = value(x)

for SB3's MLP ``f`` (policy) and ``g`` (value); the state-independent log-std is symmetric
already. Mirroring is a sign flip, so the mirrored observation entries must be centred on 0:
scale them (:class:`policies.learned.features.ScaleObservation`) rather than shift them
(``VecNormalize``'s ``norm_obs``).

``policy_kwargs``: ``mirror_obs`` (one ``+1``/``-1`` per entry of one frame; it is repeated
over stacked frames) and ``mirror_action`` (one per action entry of the platform, in its order),
plus any ``MlpPolicy`` argument. ``privileged_signs`` (one sign per entry) makes it an
asymmetric actor-critic: the last ``len(privileged_signs)`` observation entries are the
simulation's truth that :class:`train.privileged.VecPrivilegedCritic` appends in training; the
critic reads them, the actor is built on the entries before them, so at inference, where the
agent's pipeline does not make them, it acts on its own view alone.

In a left-right reflection the forward speed keeps its sign and the sideways speed and the turn
rate change it (:data:`ACTION_MIRROR_SIGNS`): the differential drive's ``[v_mps, w_radps]``
mirrors as ``[1, -1]``, the mecanum base's ``[v_mps, vy_mps, w_radps]`` as ``[1, -1, -1]``;
:func:`check_mirror_action` holds a configuration to that.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import torch
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.torch_layers import MlpExtractor
from torch import nn

__all__ = ["ACTION_MIRROR_SIGNS", "MirrorMlpPolicy", "check_mirror_action"]

Layer = Callable[[torch.Tensor], torch.Tensor]
"""A layer as a function of its input."""
Compiler = Callable[[nn.Module], Layer]
"""Gives a module (or an extractor's actor) as a :data:`Layer`."""

#: How each known action entry behaves in a left-right reflection (REP 103 axes: x forward, y
#: left, z up): x-components keep their sign, y-components and yaw rates change it.
ACTION_MIRROR_SIGNS: dict[str, float] = {"v_mps": 1.0, "vy_mps": -1.0, "w_radps": -1.0}


def check_mirror_action(signs: Sequence[float], names: Sequence[str], where: str) -> None:
    """Raise ``ValueError`` naming ``where`` unless ``signs`` has one sign per action entry
    ``names`` and each known entry's sign is its reflection's (:data:`ACTION_MIRROR_SIGNS`).

    :param signs: the configured ``mirror_action``. :param names: the env's action entries.
    :param where: the field's name in the message, e.g. ``policy_kwargs.mirror_action``.
    """
    names = list(names)
    if not isinstance(signs, list | tuple) or len(signs) != len(names):
        raise ValueError(
            f"{where}={signs!r} is out of range: must be {len(names)} signs, one per action "
            f"entry [{', '.join(names)}]"
        )
    for sign, name in zip(signs, names, strict=True):
        expected = ACTION_MIRROR_SIGNS.get(name)
        if expected is not None and sign != expected:
            verb = "keeps" if expected > 0 else "changes"
            raise ValueError(
                f"{where}={list(signs)!r} is out of range: {name} {verb} its sign in a "
                f"left-right mirror, so its sign must be {expected:+g}"
            )


class _MirrorExtractor(nn.Module):
    """Runs SB3's MLP extractor on ``x`` and ``M x``: both actor latents, the mean critic latent."""

    def __init__(self, inner: nn.Module, obs_sign: torch.Tensor) -> None:
        super().__init__()
        self.inner = inner
        self.register_buffer("obs_sign", obs_sign)
        self.latent_dim_pi = 2 * inner.latent_dim_pi
        self.latent_dim_vf = inner.latent_dim_vf

    def forward(self, features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.forward_actor(features), self.forward_critic(features)

    def forward_actor(self, features: torch.Tensor) -> torch.Tensor:
        return _both_sides(self.inner.forward_actor, features, self.obs_sign)

    def functional_actor(self, actor_of: Compiler, function_of: Compiler) -> Layer:
        """``forward_actor`` with the inner extractor's actor as ``actor_of`` gives it: the
        same operations in the same order, fewer module calls (:mod:`policies.learned.networks`
        acts with it)."""
        inner, sign = actor_of(self.inner), self.obs_sign
        return lambda features: _both_sides(inner, features, sign)

    def forward_critic(self, features: torch.Tensor) -> torch.Tensor:
        mirrored = features * self.obs_sign
        return 0.5 * (self.inner.forward_critic(features) + self.inner.forward_critic(mirrored))


class _MirrorActionNet(nn.Module):
    """``(A z1 + b + S (A z2 + b)) / 2`` for the two halves of the actor latent."""

    def __init__(self, inner: nn.Module, action_sign: torch.Tensor, half: int) -> None:
        super().__init__()
        self.inner = inner
        self.half = half
        self.register_buffer("action_sign", action_sign)

    def forward(self, latent: torch.Tensor) -> torch.Tensor:
        return _average(self.inner, latent, self.half, self.action_sign)

    def functional(self, function_of: Compiler) -> Layer:
        """``forward`` with the inner layer as ``function_of`` gives it (as above)."""
        inner, half, sign = function_of(self.inner), self.half, self.action_sign
        return lambda latent: _average(inner, latent, half, sign)


def _both_sides(actor: Layer, features: torch.Tensor, obs_sign: torch.Tensor) -> torch.Tensor:
    """Both actor latents, of ``x`` and ``M x``, side by side."""
    # an actor's row may be its own view alone (inference): the signs of its entries
    mirrored = features * obs_sign[: features.shape[-1]]
    return torch.cat([actor(features), actor(mirrored)], dim=-1)


def _average(head: Layer, latent: torch.Tensor, half: int, sign: torch.Tensor) -> torch.Tensor:
    """``(A z1 + b + S (A z2 + b)) / 2`` for the two halves of the actor latent."""
    direct = head(latent[..., :half])
    mirrored = head(latent[..., half:])
    return 0.5 * (direct + sign * mirrored)


class _SplitExtractor(nn.Module):
    """SB3's MLP extractor with the actor on the first ``actor_entries`` features and the
    critic on all of them (the rest are the critic's privileged entries)."""

    def __init__(self, actor: MlpExtractor, critic: MlpExtractor, actor_entries: int) -> None:
        super().__init__()
        self.policy_net = actor.policy_net
        self.value_net = critic.value_net
        self.actor_entries = actor_entries
        self.latent_dim_pi = actor.latent_dim_pi
        self.latent_dim_vf = critic.latent_dim_vf

    def forward(self, features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.forward_actor(features), self.forward_critic(features)

    def forward_actor(self, features: torch.Tensor) -> torch.Tensor:
        return self.policy_net(features[..., : self.actor_entries])

    def functional_actor(self, actor_of: Compiler, function_of: Compiler) -> Layer:
        """``forward_actor`` with the actor's layers as ``function_of`` gives them (as above)."""
        net, entries = function_of(self.policy_net), self.actor_entries
        return lambda features: net(features[..., :entries])

    def forward_critic(self, features: torch.Tensor) -> torch.Tensor:
        return self.value_net(features)


class MirrorMlpPolicy(ActorCriticPolicy):
    """SB3's ``MlpPolicy``, symmetrised under a reflection (module docstring).

    :param mirror_obs: the sign of each entry of one observation frame under the reflection.
    :param mirror_action: the sign of each action entry under the reflection.
    :param privileged_signs: the sign of each of the critic's privileged entries, the last of
        the observation (none: the actor and the critic read the same entries).
    """

    def __init__(
        self,
        *args: Any,
        mirror_obs: Sequence[float] = (),
        mirror_action: Sequence[float] = (),
        privileged_signs: Sequence[float] = (),
        **kwargs: Any,
    ) -> None:
        for name, signs in (
            ("mirror_obs", mirror_obs),
            ("mirror_action", mirror_action),
            ("privileged_signs", privileged_signs),
        ):
            ok = isinstance(signs, list | tuple) and all(
                not isinstance(s, bool) and isinstance(s, int | float) and s in (-1, 1)
                for s in signs
            )
            if not ok:
                raise ValueError(
                    f"MirrorMlpPolicy.{name}={signs!r} is out of range: must be a list of +1/-1"
                )
        self.mirror_obs = [float(s) for s in mirror_obs]
        self.mirror_action = [float(s) for s in mirror_action]
        self.privileged_signs = [float(s) for s in privileged_signs]
        super().__init__(*args, **kwargs)

    @property
    def actor_entries(self) -> int:
        """How many observation entries the actor reads: all but the privileged ones."""
        return int(np.prod(self.observation_space.shape)) - len(self.privileged_signs)

    def _build_mlp_extractor(self) -> None:
        if not self.privileged_signs:
            super()._build_mlp_extractor()
            return
        if self.actor_entries < 1:
            raise ValueError(
                f"MirrorMlpPolicy: privileged_signs ({len(self.privileged_signs)} signs) leave "
                f"no entry of the observation ({self.features_dim}) to the actor"
            )
        args = (self.net_arch, self.activation_fn, self.device)
        self.mlp_extractor = _SplitExtractor(
            MlpExtractor(self.actor_entries, *args),
            MlpExtractor(self.features_dim, *args),
            self.actor_entries,
        )

    def _build(self, lr_schedule: Any) -> None:
        super()._build(lr_schedule)
        n_obs = self.actor_entries
        n_act = int(np.prod(self.action_space.shape))
        frame = len(self.mirror_obs)
        if frame == 0 or n_obs % frame or len(self.mirror_action) != n_act:
            raise ValueError(
                f"MirrorMlpPolicy: mirror_obs ({frame} signs) must divide the actor's "
                f"observation ({n_obs} entries) and mirror_action needs {n_act} signs, "
                f"got {len(self.mirror_action)}"
            )
        obs_sign = torch.tensor(
            self.mirror_obs * (n_obs // frame) + self.privileged_signs, dtype=torch.float32
        )
        half = self.mlp_extractor.latent_dim_pi
        # Wrapping reuses the parameters, so the optimizer built by super()._build still holds
        # every one of them.
        self.mlp_extractor = _MirrorExtractor(self.mlp_extractor, obs_sign)
        action_sign = torch.tensor(self.mirror_action, dtype=torch.float32)
        self.action_net = _MirrorActionNet(self.action_net, action_sign, half)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(mirror_obs=self.mirror_obs, mirror_action=self.mirror_action)
        if self.privileged_signs:
            data.update(privileged_signs=self.privileged_signs)
        return data
