"""``follow-train --trained-agent DIR``: a new run that starts from a trained agent's weights.

rl-zoo3's ``--trained-agent``, for this project's agents: the new run is a run like any other
(its own folder, lanes, seeds, budget, learning-rate schedule, checkpoints, card and export),
except that its network starts from the agent's weights (and its optimiser's state) and its
normalisation from the agent's statistics (of observations and returns), instead of from
scratch. It is how an agent is trained on for longer, on other scenarios (a curriculum), on
another robot's preset or under another training reward.

The agent is a run folder, an export, a ``model.zip`` or a checkpoint ``.zip`` (as
:func:`policies.learned.ppo.agent_files` finds its files); an ensemble only with ``--seeds``,
where training seed ``k`` starts from the member ``seed-<k>`` (:func:`member_for_seed`).

Unless told otherwise the run takes the agent's algorithm, task, preset, scenarios and, without
``--hyperparams``, its own resolved hyperparameters (its ``config.yaml``); its lanes start where
a resume of the agent's own training would go on (the agent's seed + its steps), so that it
meets other people than the agent trained on (in a study, each seed from its own agent's:
:func:`train.seeds.seed_args`). With a file, the file's hyperparameters apply, and
what the weights cannot follow is refused before anything is written: another algorithm, task,
policy, network (``policy_kwargs``, but for the keys that only set the initial weights), SAC's
choice between a learned and a fixed entropy coefficient, observation or action shape, or
normalisation settings. What differs otherwise (the training reward, lanes, learning rate, ...)
is the point of training on.

What is not carried over: an off-policy learner's replay buffer (SAC starts with an empty one,
and takes ``learning_starts`` steps of random actions again before it learns), a fixed entropy
coefficient (a hyperparameter: the file's), and the step count (the run counts its own steps
from 0; its ``config.yaml`` records the agent's). The reward normalisation's statistics are
carried over as they are, as rl-zoo3 does, even where the training reward or ``gamma`` changes.
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from follow_env.tasks.person_follow import ENV_ID as PERSON_FOLLOW
from train.algos import DEFAULT_ALGO

if TYPE_CHECKING:
    from train.options import Args

__all__ = [
    "INIT_ONLY_POLICY_KWARGS",
    "TrainedAgent",
    "check_base",
    "check_fits",
    "check_spaces",
    "check_task",
    "defaults_from",
    "load_statistics",
    "member_for_seed",
    "read_trained_agent",
    "record",
    "shown_path",
    "start_from",
    "statistics_digest",
]

OPTION = "--trained-agent"
#: ``policy_kwargs`` that only set the initial weights, which the agent's replace: they may differ.
INIT_ONLY_POLICY_KWARGS = frozenset({"log_std_init", "ortho_init"})


@dataclass(frozen=True)
class TrainedAgent:
    """A trained agent to start a run from.

    :param folder: where it was given (absolute): a run, an export or a ``.zip``.
    :param model: its SB3 ``.zip`` (absolute).
    :param normalization: where its ``VecNormalize`` pickle is, or would be (it may have none).
    :param config: its run's ``config.yaml``, as read.
    :param steps: the env steps it was trained for (its model file's ``num_timesteps``).
    """

    folder: Path
    model: Path
    normalization: Path
    config: dict[str, Any]
    steps: int

    @property
    def algo(self) -> str:
        """The learner that trained it (runs older than the choice of learner: PPO)."""
        return str(self.config.get("algo", DEFAULT_ALGO))

    @property
    def args(self) -> dict[str, Any]:
        """The options it was trained with, as its ``config.yaml`` holds them."""
        saved = self.config.get("args")
        return saved if isinstance(saved, dict) else {}

    @property
    def next_seed(self) -> int | None:
        """Where a resume of its own training would start its lanes: its seed + its steps
        (None if its ``config.yaml`` records no seed)."""
        seed = self.args.get("seed")
        if isinstance(seed, int) and not isinstance(seed, bool):
            return seed + self.steps
        return None

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
    if not files.config.is_file():
        raise ValueError(
            f"{OPTION} {path}: no {files.config.name} at {files.config}; an agent needs the "
            "configuration its run wrote (a run or export folder has it)"
        )
    try:
        config = runs.read_config(files.config)
    except ValueError as e:
        raise ValueError(f"{OPTION}: {e}") from None
    try:  # SB3 keeps the step count in the zip's JSON "data": no torch load needed for it
        with zipfile.ZipFile(files.model) as archive:
            steps = int(json.loads(archive.read("data"))["num_timesteps"])
    except (OSError, zipfile.BadZipFile, KeyError, ValueError, TypeError) as e:
        raise ValueError(f"{OPTION}: {files.model}: not a readable model ({e})") from None
    return TrainedAgent(path, files.model.absolute(), files.normalization.absolute(), config, steps)


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


def defaults_from(agent: TrainedAgent, args: Args) -> dict[str, Any]:
    """The options a run from ``agent`` takes from it where the command line left them out:
    the algorithm, the preset and scenarios it trained on, its task without ``--hyperparams``,
    and the seed its lanes start from: the agent's seed + its steps, where a resume of its own
    training would go on (its lanes were seed + j), so that the run meets new people.

    :raises ValueError: for an ``--algo`` other than the agent's.
    """
    if args.algo is not None and args.algo != agent.algo:
        raise ValueError(
            f"--algo {args.algo}: {OPTION} {agent.folder} is a {agent.algo} agent; its weights "
            f"fit {agent.algo} only: leave --algo out"
        )
    given: dict[str, Any] = {"algo": agent.algo}
    saved = agent.args
    if args.hyperparams is None and args.env_id is None:
        given["env_id"] = agent.env_id
    scenarios = saved.get("scenarios")
    if args.scenarios is None and isinstance(scenarios, list):
        given["scenarios"] = tuple(scenarios)
    if args.env_config is None and isinstance(saved.get("env_config"), str):
        given["env_config"] = saved["env_config"]
    if args.seed is None and agent.next_seed is not None:
        given["seed"] = agent.next_seed
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


def _learned_entropy(hp: dict[str, Any]) -> bool | None:
    """Whether SAC's entropy coefficient is learned (``auto``, ``auto_<x>``: a saved tensor
    of the agent's) or fixed (a number: a hyperparameter); None for a learner without one."""
    if "ent_coef" not in hp:
        return None
    value = hp["ent_coef"]
    return isinstance(value, str) and value.startswith("auto")


def check_fits(agent: TrainedAgent, hp: dict[str, Any], where: str) -> None:
    """Refuse hyperparameters ``hp`` (from ``where``) the agent's weights cannot follow: another
    policy, network, normalisation or kind of entropy coefficient. Spaces are checked once the
    env is built (:func:`check_base`, :func:`check_spaces`).

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
    learned = _learned_entropy(mine), _learned_entropy(hp)
    if None not in learned and learned[0] != learned[1]:
        kind = {True: "learned", False: "fixed"}
        raise ValueError(
            f"{where}: ent_coef={hp['ent_coef']!r} ({kind[learned[1]]}), but {OPTION} "
            f"{agent.folder} learned with ent_coef={mine['ent_coef']!r} "
            f"({kind[learned[0]]}): give a {kind[learned[0]]} one (a fixed value of the file's "
            "own is used as given)"
        )
    if hp.get("normalize") and not agent.normalization.is_file():
        raise ValueError(
            f"{OPTION} {agent.folder}: no {agent.normalization.name} beside "
            f"{agent.model.name}, but its hyperparameters normalise: the statistics its weights "
            "expect are missing"
        )


def _saved_size(agent: TrainedAgent, space: str) -> int | None:
    """How many numbers the env's ``space`` (observation or action) had where the agent
    trained, from its ``config.yaml`` (None if it does not say)."""
    spaces = agent.config.get("env_spaces")
    box = spaces.get(space) if isinstance(spaces, dict) else None
    low = box.get("low") if isinstance(box, dict) else None
    return len(low) if isinstance(low, list) else None


def check_base(agent: TrainedAgent, base: Any) -> None:
    """Refuse an env (below the agent's view) other than the one the agent trained on: another
    number of actions (another platform) or of observations (another sensor).

    :raises ValueError: naming both sizes.
    """
    for space, what in (("action", "acts with"), ("observation", "observes")):
        theirs, ours = _saved_size(agent, space), getattr(base, f"{space}_space").shape[0]
        if theirs is not None and theirs != ours:
            raise ValueError(
                f"{OPTION} {agent.folder}: the agent {what} {theirs} numbers, this run's env "
                f"{'takes' if space == 'action' else 'gives'} {ours} (another platform or "
                "sensor, through env_kwargs or the preset): its weights cannot"
            )


def check_spaces(agent: TrainedAgent, venv: Any) -> None:
    """Refuse an agent env ``venv`` (the view: wrappers and frame stack) whose observation
    shape is not the agent's.

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


def load_statistics(venv: Any, agent: TrainedAgent) -> None:
    """Give the run's ``VecNormalize`` (built from its own hyperparameters: its gamma and
    clipping) the agent's running statistics of observations and returns.

    :raises ValueError: naming the agent's file if it cannot be read or does not fit.
    """
    import pickle

    from stable_baselines3.common.vec_env import VecNormalize, unwrap_vec_normalize

    normalize = unwrap_vec_normalize(venv)
    if normalize is None:
        return
    path = agent.normalization
    try:
        with path.open("rb") as f:
            saved = pickle.load(f)
    except Exception as e:  # OSError, pickle and the classes it rebuilds raise their own
        raise ValueError(f"{OPTION}: {path}: not readable statistics ({e})") from None
    if not isinstance(saved, VecNormalize):
        raise ValueError(f"{OPTION}: {path}: holds a {type(saved).__name__}, not VecNormalize")
    if normalize.norm_obs:  # (SB3 keeps no observation statistics without it)
        ours, theirs = normalize.obs_rms, getattr(saved, "obs_rms", None)
        shape = getattr(getattr(theirs, "mean", None), "shape", None)
        if shape != ours.mean.shape:
            raise ValueError(
                f"{OPTION}: {path}: statistics of observations of shape {shape}, this run's "
                f"are {ours.mean.shape}"
            )
        normalize.obs_rms = theirs
    normalize.ret_rms = saved.ret_rms


#: Saved tensors that are hyperparameters, not learned: the run's file gives them (SAC's fixed
#: entropy coefficient).
_NOT_LEARNED = frozenset({"ent_coef_tensor"})


def start_from(model: Any, agent: TrainedAgent) -> None:
    """Give ``model`` (a new one, of the agent's algorithm and network) the agent's weights,
    its optimisers' state and its other learned tensors (SAC's learned entropy coefficient).

    :raises ValueError: naming the agent if its model file cannot be read or does not fit.
    """
    from stable_baselines3.common.save_util import load_from_zip_file
    from stable_baselines3.common.utils import get_device

    try:
        _, params, variables = load_from_zip_file(agent.model, device=get_device("cpu"))
    except Exception as e:  # zipfile, pickle and torch raise their own
        raise ValueError(f"{OPTION}: {agent.model}: not a readable model ({e})") from None
    if not params:
        raise ValueError(f"{OPTION}: {agent.model}: holds no weights")
    try:
        model.set_parameters(params, exact_match=True, device="cpu")
        for name, value in (variables or {}).items():
            if value is not None and name not in _NOT_LEARNED:
                _set_tensor(model, name, value)
    except (RuntimeError, ValueError, KeyError, AttributeError) as e:
        problem = " ".join(str(e).split())[:300]
        raise ValueError(
            f"{OPTION}: {agent.model}: its weights do not fit this run's network ({problem})"
        ) from None


def _set_tensor(model: Any, name: str, value: Any) -> None:
    """``model.<name>.data = value`` (SB3's ``recursive_setattr``), shapes checked."""
    target = model
    for part in name.split("."):
        target = getattr(target, part)
    if tuple(target.shape) != tuple(value.shape):
        raise ValueError(f"{name}: shape {tuple(value.shape)}, the run's {tuple(target.shape)}")
    target.data.copy_(value.data)


def statistics_digest(agent: TrainedAgent, normalise: bool) -> dict[str, str]:
    """The SHA-256 of the agent's files a run starts from: its model, and its statistics if
    the run normalises."""
    from train.export import sha256

    files = {agent.model.name: sha256(agent.model)}
    if normalise:
        files[agent.normalization.name] = sha256(agent.normalization)
    return files


def record(agent: TrainedAgent, digests: dict[str, str]) -> dict[str, Any]:
    """What a run's ``config.yaml`` says of the agent it started from: where it was, how far
    it had trained, and its files' SHA-256 (``digests``), so that the start can be checked."""
    return {"path": str(agent.folder), "algo": agent.algo, "steps": agent.steps, "sha256": digests}


def shown_path(path: str | Path) -> str:
    """``path`` as a model card shows it: relative to the current folder if inside it (a
    shipped agent's ``policies/agents/...``), else as it is."""
    path = Path(path)
    try:
        return str(path.relative_to(Path.cwd()))
    except ValueError:
        return str(path)
