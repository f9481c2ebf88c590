"""The policies of an evaluation grid, named and checked in one place.

A grid names each policy by a spec: a registered name (``"pn:thesis"``, ``"ppo_law"``), a
trained agent's folder, a :class:`policies.Policy` object, each optionally on another platform
(``"pn@mecanum"``). :func:`checked_policy` builds one and refuses what cannot run, for
:func:`eval.rollout.rollout` and ``follow-eval run`` alike, before any episode starts.
"""

from __future__ import annotations

from pathlib import Path

from follow_env.platforms import get_platform
from follow_env.tasks import task_for_env
from policies import Policy, available_policies, for_platform, make_policy

__all__ = ["PolicySpec", "checked_policy", "policy_spec"]

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
