"""The policies of an evaluation grid, named and checked in one place.

A grid names each policy by a spec: a registered name (``"pn:thesis"``, ``"ppo_law"``), a
trained agent's folder, a :class:`policies.Policy` object, each optionally on another platform
(``"pn@mecanum"``). :func:`checked_policy` builds one and refuses what cannot run, for
:func:`eval.rollout.rollout` and ``follow-eval run`` alike, before any episode starts.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from follow_env.platforms import get_platform
from follow_env.tasks import task_for_env
from policies import Policy, available_policies, for_platform, make_policy

__all__ = ["PolicySpec", "checked_policy", "model_digest", "policy_spec"]

PolicySpec = str | Policy


def policy_spec(spec: PolicySpec) -> tuple[PolicySpec, str | None]:
    """``(policy, platform)`` of a spec: ``"pn@mecanum"`` runs ``pn`` on the ``mecanum``
    platform (its episodes labelled ``pn:tuned@mecanum``); a name without ``@``, or a policy
    object, runs on the configuration's platform.

    :raises ValueError: for an unknown platform (naming the known ones).
    """
    if isinstance(spec, str) and "@" in spec:
        name, _, platform = spec.rpartition("@")
        try:
            get_platform(platform)
        except ValueError:
            if Path(spec).exists():  # a model's path with an "@" in it (runs/agent@v2)
                return spec, None
            raise
        return name, platform
    return spec, None


def checked_policy(given: PolicySpec, task: str) -> tuple[Policy, str | None]:
    """The policy a spec names for ``task``, and the platform it names (None: the config's).

    :raises ValueError: for an unknown name or platform, a registered policy of another task,
        an agent trained on another task's env (naming that task), or a policy the platform
        cannot run; each message names the policy.
    """
    spec, platform = policy_spec(given)
    if isinstance(spec, str):
        for_task = set(available_policies(task))
        if spec in set(available_policies()) - for_task:
            raise ValueError(
                f"policy {spec!r} is not for the {task} task; its policies: "
                + ", ".join(sorted(for_task))
            )
        policy = make_policy(spec, task)  # raises ValueError listing the known names
    elif isinstance(spec, Policy):
        policy = spec
    else:
        raise ValueError(f"policy {spec!r} is neither a policy name nor a Policy")
    # An agent trained on another task's env is sent to that task (its platform and
    # observation would otherwise be blamed).
    env_id = getattr(policy, "env_id", None)
    if env_id is not None and (trained_for := task_for_env(env_id).name) != task:
        raise ValueError(
            f"{policy.name!r} was trained on {env_id}, not on the {task} task: run it on the "
            f"{trained_for} task (--task {trained_for})"
        )
    if platform is not None:  # a law the platform cannot run raises
        for_platform(policy, tuple(a.name for a in get_platform(platform).actions))
    return policy, platform


def model_digest(policy: object) -> str | None:
    """SHA-256 (hex) of the files a learned policy was loaded from, None for any other policy.

    A trained agent's name and ``repr`` hold only the path it was given (often relative), so
    two runs of ``runs/agent`` may hold two different models: the digest tells them apart. It
    covers each agent's ``model.zip`` (or checkpoint), its normalisation statistics and its
    ``config.yaml`` (:func:`policies.learned.ppo.agent_files`), in member order for an
    ensemble; a file the agent does without (no statistics) counts as absent.
    """
    from policies.learned.ensemble import EnsemblePolicy
    from policies.learned.ppo import PPOPolicy, agent_files

    if isinstance(policy, PPOPolicy):
        folders = [policy.path]
    elif isinstance(policy, EnsemblePolicy):
        folders = list(policy.members)
    else:
        return None
    digest = hashlib.sha256()
    for folder in folders:
        files = agent_files(folder)
        # by role, not by file name: a checkpoint's files are named after its step count
        for role, path in (
            ("model", files.model),
            ("normalization", files.normalization),
            ("config", files.config),
        ):
            digest.update(role.encode("ascii"))
            if not path.is_file():
                digest.update(b"\0absent\0")
                continue
            data = path.read_bytes()  # an agent's files are at most a few MB
            digest.update(b"\0%d\0" % len(data))  # lengths keep the files' bounds apart
            digest.update(data)
    return digest.hexdigest()
