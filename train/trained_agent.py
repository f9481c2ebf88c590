"""``follow-train --trained-agent DIR``: a new run that starts from a trained agent's weights.

rl-zoo3's ``--trained-agent``, for this project's agents: the new run is a run like any other
(its own folder, lanes, seeds, budget, learning-rate schedule, checkpoints, card and export),
except that its network starts from the agent's weights (and its optimiser's state) and its
observation normalisation from the agent's statistics, instead of from scratch. It is how an
agent is trained on for longer, on other scenarios (a curriculum), on another robot's preset or
under another training reward.

The agent is a run folder, an export, a ``model.zip`` or a checkpoint ``.zip`` (as
:func:`policies.learned.ppo.agent_files` finds its files); an ensemble only with ``--seeds``,
where training seed ``k`` starts from the member ``seed-<k>`` (:func:`member_for_seed`).

Without ``--hyperparams`` the run trains with the agent's own resolved hyperparameters (its
``config.yaml``), on its scenarios and with its algorithm. With a file, the file's apply, and
what the weights cannot follow is refused before anything is written: another algorithm, policy,
network (``policy_kwargs``, but for the keys that only set the initial weights), observation or
action shape, or normalisation settings. What differs otherwise (the training reward, lanes,
learning rate, ...) is the point of training on.

What is not carried over: an off-policy learner's replay buffer (SAC starts with an empty one,
and collects ``learning_starts`` steps again before it learns) and the step count (the run
counts its own steps from 0; its ``config.yaml`` records the agent's).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from follow_env.tasks.person_follow import ENV_ID as PERSON_FOLLOW
from train.algos import DEFAULT_ALGO

__all__ = [
    "INIT_ONLY_POLICY_KWARGS",
    "TrainedAgent",
    "check_fits",
    "check_task",
    "member_for_seed",
    "read_trained_agent",
    "start_from",
]

OPTION = "--trained-agent"
#: ``policy_kwargs`` that only set the initial weights, which the agent's replace: they may differ.
INIT_ONLY_POLICY_KWARGS = frozenset({"log_std_init", "ortho_init"})


@dataclass(frozen=True)
class TrainedAgent:
    """A trained agent to start a run from.

    :param folder: where it was given (absolute): a run, an export or a ``.zip``.
    :param model: its SB3 ``.zip`` (absolute).
    :param normalization: its ``VecNormalize`` pickle, None if it has none.
    :param config: its run's ``config.yaml``, as read.
    """

    folder: Path
    model: Path
    normalization: Path | None
    config: dict[str, Any]

    @property
    def algo(self) -> str:
        """The learner that trained it (runs older than the choice of learner: PPO)."""
        return str(self.config.get("algo", DEFAULT_ALGO))

    @property
    def hyperparams(self) -> dict[str, Any]:
        """Its resolved hyperparameters, as its ``config.yaml`` holds them."""
        return self.config["hyperparams"]

    @property
    def env_id(self) -> str:
        """The task it was trained on (runs older than the record of it: PersonFollow's)."""
        return str(self.config.get("env_id") or PERSON_FOLLOW)

    @property
    def where(self) -> str:
        """Its hyperparameters' place, for error messages."""
        return f"{self.folder} (config.yaml [hyperparams])"


def read_trained_agent(path: Path) -> TrainedAgent:
    """The agent at ``path``, its files checked to exist and its configuration to be a run's.

    :raises ValueError: naming the option and the path: no such agent, an ensemble (with
        ``--seeds`` each seed takes its member: :func:`member_for_seed`), a missing model or
        configuration file.
    """
    from policies.learned.ensemble import ENSEMBLE
    from policies.learned.ppo import AgentLoadError, agent_files
    from train import run as runs

    path = Path(path).absolute()
    if not path.exists():
        raise ValueError(f"{OPTION} {path}: no such agent (give a run or export folder or a .zip)")
    if path.is_dir() and (path / ENSEMBLE).is_file():
        raise ValueError(
            f"{OPTION} {path}: an ensemble; name one member (e.g. {path / 'seed-0'}), or give "
            "--seeds: training seed k then starts from the member seed-<k>"
        )
    try:
        files = agent_files(path)
    except AgentLoadError as e:
        raise ValueError(f"{OPTION}: {e}") from None
    if not files.model.is_file():
        raise ValueError(f"{OPTION} {path}: no {files.model.name} in it; not a trained agent")
    try:
        config = runs.read_config(files.config)
    except ValueError as e:
        raise ValueError(f"{OPTION}: {e}") from None
    normalization = files.normalization if files.normalization.is_file() else None
    return TrainedAgent(path, files.model.absolute(), normalization, config)


def member_for_seed(path: Path, k: int) -> Path:
    """The agent training seed ``k`` of a study starts from: ``path`` itself, or for an
    ensemble its member ``seed-<k>`` (as ``follow-train --seeds --export`` names them).

    :raises ValueError: for an ensemble that lists no ``seed-<k>``.
    """
    from policies.learned.ensemble import ENSEMBLE, member_folders
    from policies.learned.ppo import AgentLoadError

    path = Path(path).absolute()
    if not (path.is_dir() and (path / ENSEMBLE).is_file()):
        return path
    try:
        members = member_folders(path / ENSEMBLE)
    except AgentLoadError as e:
        raise ValueError(f"{OPTION}: {e}") from None
    for folder in members:
        if folder.resolve() == (path / f"seed-{k}").resolve():
            return folder.absolute()
    names = ", ".join(folder.name for folder in members)
    raise ValueError(
        f"{OPTION} {path}: the ensemble has no member seed-{k} for training seed {k} (its "
        f"members: {names}); give --seeds that match its members"
    )


def defaults_from(agent: TrainedAgent, args: Any) -> dict[str, Any]:
    """The options a run from ``agent`` takes from it where the command line left them out:
    the algorithm, the scenarios it trained on, and without ``--hyperparams`` its task.

    :raises ValueError: for an ``--algo`` other than the agent's.
    """
    if args.algo is not None and args.algo != agent.algo:
        raise ValueError(
            f"--algo {args.algo}: {OPTION} {agent.folder} is a {agent.algo} agent; its weights "
            f"fit {agent.algo} only: leave --algo out"
        )
    given: dict[str, Any] = {"algo": agent.algo}
    saved = agent.config.get("args") if isinstance(agent.config.get("args"), dict) else {}
    if args.hyperparams is None and args.env_id is None:
        given["env_id"] = agent.env_id
    scenarios = saved.get("scenarios")
    if args.scenarios is None and isinstance(scenarios, list):
        given["scenarios"] = tuple(scenarios)
    return given


def check_task(agent: TrainedAgent, env_id: str) -> None:
    """Refuse a run on another task than the agent's.

    :raises ValueError: naming both.
    """
    if env_id != agent.env_id:
        raise ValueError(
            f"{OPTION} {agent.folder}: a {agent.env_id} agent; this run trains on {env_id} "
            "(--env-id, or the --hyperparams file's section): give the agent's task"
        )


def _policy_kwargs(hp: dict[str, Any]) -> dict[str, Any]:
    kwargs = hp.get("policy_kwargs") or {}
    return {k: v for k, v in kwargs.items() if k not in INIT_ONLY_POLICY_KWARGS}


def check_fits(agent: TrainedAgent, hp: dict[str, Any], where: str) -> None:
    """Refuse hyperparameters ``hp`` (from ``where``) the agent's weights cannot follow: another
    policy, network or normalisation. Spaces are checked once the env is built
    (:func:`check_spaces`).

    :raises ValueError: naming both values and what to do.
    """
    mine = agent.hyperparams
    for key, theirs, ours in (
        ("policy", mine.get("policy"), hp.get("policy")),
        ("policy_kwargs", _policy_kwargs(mine), _policy_kwargs(hp)),
        ("normalize", mine.get("normalize"), hp.get("normalize")),
        ("frame_stack", mine.get("frame_stack", 1), hp.get("frame_stack", 1)),
    ):
        if theirs != ours:
            raise ValueError(
                f"{where}: {key}={ours!r}, but {OPTION} {agent.folder} was trained with "
                f"{key}={theirs!r}: its weights and statistics fit its own; give the agent's "
                f"{key} (or leave --hyperparams out to train with the agent's own)"
            )
    if hp.get("normalize") and agent.normalization is None:
        raise ValueError(
            f"{OPTION} {agent.folder}: no vecnormalize.pkl beside {agent.model.name}, but its "
            "hyperparameters normalise: the statistics its weights expect are missing"
        )


def check_spaces(agent: TrainedAgent, venv: Any) -> None:
    """Refuse an agent env ``venv`` whose observation or action shape is not the agent's.

    :raises ValueError: naming both shapes.
    """
    saved = agent.config.get("agent_observation_shape")
    ours = list(venv.observation_space.shape)
    if isinstance(saved, list) and saved != ours:
        raise ValueError(
            f"{OPTION} {agent.folder}: the agent sees observations of shape {saved}, this "
            f"run's view gives {ours} (its vec_env_wrapper list or frame_stack differ): the "
            "weights cannot take them"
        )
    spaces = agent.config.get("env_spaces")
    action = spaces.get("action") if isinstance(spaces, dict) else None
    low = action.get("low") if isinstance(action, dict) else None
    if isinstance(low, list) and len(low) != venv.action_space.shape[0]:
        raise ValueError(
            f"{OPTION} {agent.folder}: the agent acts with {len(low)} numbers, this run's env "
            f"takes {venv.action_space.shape[0]}: another platform's agent"
        )


def start_from(model: Any, agent: TrainedAgent) -> int:
    """Give ``model`` (a new one, of the agent's algorithm and network) the agent's weights,
    its optimisers' state and its other saved tensors (SAC's entropy coefficient); returns the
    env steps the agent was trained for.

    :raises ValueError: naming the agent if its model file cannot be read or does not fit.
    """
    from stable_baselines3.common.save_util import load_from_zip_file
    from stable_baselines3.common.utils import get_device

    try:
        data, params, variables = load_from_zip_file(agent.model, device=get_device("cpu"))
    except Exception as e:  # zipfile, pickle and torch raise their own
        raise ValueError(f"{OPTION}: {agent.model}: not a readable model ({e})") from None
    if not params:
        raise ValueError(f"{OPTION}: {agent.model}: holds no weights")
    try:
        model.set_parameters(params, exact_match=True, device="cpu")
        for name, value in (variables or {}).items():
            if value is not None:
                _set_tensor(model, name, value)
    except (RuntimeError, ValueError, KeyError, AttributeError) as e:
        problem = " ".join(str(e).split())[:300]
        raise ValueError(
            f"{OPTION}: {agent.model}: its weights do not fit this run's network ({problem})"
        ) from None
    return int((data or {}).get("num_timesteps", 0))


def _set_tensor(model: Any, name: str, value: Any) -> None:
    """``model.<name>.data = value`` (SB3's ``recursive_setattr``), shapes checked."""
    target = model
    for part in name.split("."):
        target = getattr(target, part)
    if tuple(target.shape) != tuple(value.shape):
        raise ValueError(f"{name}: shape {tuple(value.shape)}, the run's {tuple(target.shape)}")
    target.data.copy_(value.data)


def record(agent: TrainedAgent, steps: int) -> dict[str, Any]:
    """What a run's ``config.yaml`` says of the agent it started from: where it was, how far
    it had trained, and its files' SHA-256, so that the start can be checked later."""
    from train.export import sha256

    files = {agent.model.name: sha256(agent.model)}
    if agent.normalization is not None:
        files[agent.normalization.name] = sha256(agent.normalization)
    return {"path": str(agent.folder), "algo": agent.algo, "steps": steps, "sha256": files}
