"""A trained agent (``follow-train``) behind the :class:`~policies.base.Policy` protocol.

``make_policy("ppo")`` is the shipped agent (``policies/agents/ppo``); ``make_policy(path)``
loads any other: a run folder (``runs/ppo-<timestamp>``, ``runs/sac-<timestamp>`` ...), its
``model.zip``, or a checkpoint (``runs/ppo-<timestamp>/checkpoints/ppo_<steps>_steps.zip``). An
agent is three files:

- ``model.zip``: the SB3 model (PPO or SAC, or sb3-contrib's RecurrentPPO);
- ``vecnormalize.pkl``: the observation normalisation statistics (a checkpoint has its own,
  ``ppo_vecnormalize_<steps>_steps.pkl``; a run that does not normalise has none);
- ``config.yaml``: the run's resolved configuration, whose ``algo``, ``vec_env_wrapper`` list,
  ``frame_stack`` and env spaces say how the agent sees the env (no ``algo``: PPO).

Loading checks them against each other and against the tasks, and refuses a folder that would
act wrongly without a word (:class:`AgentLoadError`, naming the file): an ``env_id`` of no
task, an observation or action box with a NaN bound or low > high, statistics whose
``norm_obs`` the configuration contradicts, or whose mean, variance, ``epsilon`` or
``clip_obs`` are unusable (NaN, negative variances).

The policy rebuilds the agent's view from the configuration with the feature pipeline that
training wraps (:mod:`policies.learned.features`): extra observation features, normalisation
with the saved statistics (frozen), stacked frames. So the agent gets exactly the input it was
trained on, acts deterministically (:mod:`policies.learned.networks`: PPO's Gaussian mean,
SAC's squashed mean rescaled onto the action box, RecurrentPPO's mean after its LSTM, whose
state the policy keeps per lane), and its action is mapped back to
SI by the same code: the action of the platform it was trained on (``config.yaml``'s
``platform`` and ``env_spaces.action.names``; an agent saved without them was trained on the
differential drive, ``[v_mps, w_radps]``). An agent of another task (LineTrace-v0's 25
readings) works the same way: its observation's size comes from the saved ``env_spaces``. The
policy names its platform and action (``platform``, ``action_names``), and
:func:`policies.adapt.for_platform` refuses it on a platform whose action differs.
:meth:`PPOPolicy.reset` clears the pipeline's memory (frame stack, command, observation age) and
a recurrent agent's LSTM state. No training code is imported.

Batched acting (:meth:`PPOPolicy.act_batch`) runs the feature pipeline over all lanes at once
but the network one lane at a time: torch's batched matrix products round differently from a
single row (in float32 up to 3e-7 on the shipped agent; in float64, as it acts now, a rare
action could still round apart), and batched evaluation promises bitwise single episodes.

torch and stable-baselines3 (sb3-contrib for a recurrent agent) load only when an agent is
built; a loaded model is shared by the policies built from the same files (each keeps its own
memory).
"""

from __future__ import annotations

import re
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import yaml

from follow_env.sim.checks import load_yaml, utf8_problem, yaml_problem
from follow_env.tasks.person_follow.spec import AHEAD, AHEAD_SETTINGS, SPEC
from policies.base import OBS_SIZES, lane_flags, real_obs, validate_obs_batch, validate_obs_row
from policies.learned.checks import (
    ENV_IDS,
    box_problem,
    normalized_observations,
    statistics_problem,
)
from policies.learned.feature import wrapper_entries
from policies.learned.features import Box, Feature, FrameStack, NormalizeObservation, Pipeline
from policies.learned.networks import ALGOS, Memory, load_network

__all__ = [
    "AGENTS",
    "DEFAULT_AGENT",
    "SHIPPED",
    "AgentFiles",
    "AgentLoadError",
    "PPOPolicy",
    "agent_files",
    "file_version",
    "load_agent",
    "load_default",
    "load_shipped",
    "resolve_path",
    "shipped_name",
]

#: The shipped agents' folder: ``agents/<name>`` is built by ``make_policy("<name>")``.
AGENTS = Path(__file__).parents[1] / "agents"
#: The shipped agents: each folder of :data:`AGENTS` with the name and task
#: :func:`policies.registry.make_policy` builds it under (the registry registers this table, and
#: a model card names the copy an export wrote into one of these folders).
SHIPPED: dict[str, tuple[str, str]] = {
    "ppo": ("ppo", "person_follow"),  # PersonFollow's agent
    # the mecanum base's (its action is [v_mps, vy_mps, w_radps]: ppo_mecanum@mecanum)
    "ppo_mecanum": ("ppo_mecanum", "person_follow"),
    # reads the reading ahead too (train/configs/ppo_ahead.yaml's weights, the view of
    # ppo_ahead_gated.yaml: the jump gate, left out of training); evaluation gives it the
    # reading, a robot's perception must publish it
    "ppo_ahead": ("ppo_ahead", "person_follow"),
    # reads ahead and starts from pn:thesis's command, following 1.1 m behind in training
    # (train/configs/ppo_ahead_law_far.yaml, the gate added after training); its perception
    # must publish the reading ahead
    "ppo_law": ("ppo_law", "person_follow"),
    # the mean of two agents' actions (policies.learned.ensemble: the folder's ensemble.yaml
    # lists them), seeds 0 and 1 of train/configs/ppo_ahead_law_wide.yaml (ppo_law's view and
    # reward with the headway, networks of 128 x 128) trained at once, one torch thread each,
    # the gate added after training: of the shipped agents it meets the most of the dominance
    # table, and is significantly worse than the best law on none of its lines
    "ppo_ensemble": ("ppo_ensemble", "person_follow"),
    "ppo_line": ("ppo", "line_trace"),  # LineTrace-v0's agent
}
#: The shipped agent, trained by ``follow-train --export policies/agents/ppo``.
DEFAULT_AGENT = AGENTS / "ppo"
#: The platform of an agent whose configuration names none (saved before platforms were named).
LEGACY_PLATFORM = "diff_drive"
MODEL = "model.zip"
NORMALIZATION = "vecnormalize.pkl"
CONFIG = "config.yaml"
_CHECKPOINT = re.compile(r"^(?P<prefix>.+)_(?P<steps>\d+)_steps\.zip$")


class AgentLoadError(ValueError):
    """A missing, corrupt or mismatched agent file; the message names the file."""


@dataclass(frozen=True)
class AgentFiles:
    """Where an agent's files are.

    :param model: the SB3 ``.zip``.
    :param normalization: the ``VecNormalize`` pickle that belongs to it.
    :param config: the run's ``config.yaml``.
    """

    model: Path
    normalization: Path
    config: Path


def agent_files(path: str | Path) -> AgentFiles:
    """Find an agent's files from a run folder, a ``model.zip`` or a checkpoint ``.zip``.

    :raises AgentLoadError: if ``path`` or the model file does not exist.
    """
    path = Path(path)
    if path.is_dir():
        return AgentFiles(path / MODEL, path / NORMALIZATION, path / CONFIG)
    if path.suffix != ".zip":
        raise AgentLoadError(f"{path}: no such agent (give a run folder or a .zip model file)")
    if not path.exists():
        raise AgentLoadError(f"{path}: model file not found")
    match = _CHECKPOINT.match(path.name)
    if match:  # checkpoints/ppo_<steps>_steps.zip: statistics beside it, config one level up
        stats = path.with_name(f"{match['prefix']}_vecnormalize_{match['steps']}_steps.pkl")
        config = path.parent / CONFIG
        return AgentFiles(path, stats, config if config.exists() else path.parent.parent / CONFIG)
    return AgentFiles(path, path.with_name(NORMALIZATION), path.with_name(CONFIG))


class _Statistics(NamedTuple):
    """What inference needs of a saved ``VecNormalize``."""

    norm_obs: bool
    obs_rms: Any
    epsilon: float
    clip_obs: float


def _wrapper_entries(value: Any, where: Path) -> list[tuple[str, dict[str, Any]]]:
    """rl-zoo3's ``vec_env_wrapper`` list as ``[(name, kwargs), ...]``."""
    out = []
    for entry in wrapper_entries(value):
        if isinstance(entry, str):
            out.append((entry, {}))
        elif isinstance(entry, dict) and len(entry) == 1:
            name, kwargs = next(iter(entry.items()))
            if not isinstance(name, str) or not isinstance(kwargs or {}, dict):
                raise AgentLoadError(f"{where}: vec_env_wrapper entry {entry!r} is malformed")
            out.append((name, dict(kwargs or {})))
        else:
            raise AgentLoadError(f"{where}: vec_env_wrapper entry {entry!r} is malformed")
    return out


def _box(spaces: dict[str, Any], key: str, where: Path) -> Box:
    """``env_spaces.<key>`` as a :class:`Box`, checked (:func:`~.checks.check_box`)."""
    try:
        low, high = spaces[key]["low"], spaces[key]["high"]
        box = Box(low, high, spaces[key].get("names"))
    except (KeyError, TypeError, ValueError, AttributeError) as e:
        raise AgentLoadError(f"{where}: env_spaces.{key} is not a box ({e})") from None
    problem = box_problem(box, low, high)
    if problem is not None:
        raise AgentLoadError(f"{where}: env_spaces.{key} {problem}")
    return box


class _Loaded:
    """An agent's model, configuration and statistics, read once per process (keyed by file
    versions)."""

    def __init__(self, files: AgentFiles) -> None:
        if not files.model.exists():
            raise AgentLoadError(f"{files.model}: model file not found")
        if not files.config.exists():
            raise AgentLoadError(f"{files.config}: the agent's config.yaml is missing")
        where = files.config
        try:
            config = load_yaml(files.config.read_text(encoding="utf-8"))
        except OSError as e:
            raise AgentLoadError(f"{where}: not a readable configuration: {e}") from None
        except UnicodeDecodeError as e:
            raise AgentLoadError(f"{where}: {utf8_problem(e)}") from None
        except yaml.YAMLError as e:
            raise AgentLoadError(f"{where}: not valid YAML: {yaml_problem(e)}") from None
        if not isinstance(config, dict) or not isinstance(config.get("hyperparams"), dict):
            raise AgentLoadError(f"{where}: not a usable agent configuration (no 'hyperparams')")
        hp = config["hyperparams"]
        if not isinstance(config.get("env_spaces"), dict):
            raise AgentLoadError(f"{where}: not a usable agent configuration (no 'env_spaces')")
        self.observation_box = _box(config["env_spaces"], "observation", where)
        self.action_box = _box(config["env_spaces"], "action", where)
        self.action_names = self.action_box.entry_names()
        self.platform = config.get("platform", LEGACY_PLATFORM)
        if not isinstance(self.platform, str):
            raise AgentLoadError(f"{where}: platform={self.platform!r} must be a platform's name")
        #: The perception settings the agent was trained with (``env_kwargs.perception``), the
        #: reading ahead's among them; None: the configuration's defaults.
        env_kwargs = hp.get("env_kwargs") or {}
        self.perception = env_kwargs.get("perception") if isinstance(env_kwargs, dict) else None
        self.env_id = config.get("env_id", SPEC.env_id)
        if self.env_id not in ENV_IDS:
            raise AgentLoadError(
                f"{where}: env_id={self.env_id!r} is out of range: must be one of "
                + ", ".join(map(repr, ENV_IDS))
            )
        self.wrappers = _wrapper_entries(hp.get("vec_env_wrapper"), where)
        self.frame_stack = hp.get("frame_stack", 1)
        if (
            isinstance(self.frame_stack, bool)
            or not isinstance(self.frame_stack, int)
            or self.frame_stack < 1
        ):
            raise AgentLoadError(
                f"{where}: frame_stack={self.frame_stack!r} must be an integer >= 1"
            )
        try:
            Pipeline(
                Pipeline.from_wrappers(self.wrappers), self.observation_box, self.action_box, 1
            )
        except (ValueError, TypeError) as e:
            raise AgentLoadError(f"{where}: the agent's view cannot be built: {e}") from None
        self.normalization = None
        try:
            norm_obs = normalized_observations(hp.get("normalize"))
        except ValueError as e:
            raise AgentLoadError(f"{where}: {e}") from None
        if norm_obs is not None:
            self.normalization = self._load_normalization(files.normalization, norm_obs, where)
        self.files = files
        #: The learner (``config.yaml``'s ``algo``; runs saved before there was one are PPO's).
        self.algo = config.get("algo", "ppo")
        if self.algo not in ALGOS:
            raise AgentLoadError(f"{where}: algo={self.algo!r} is not one of {', '.join(ALGOS)}")
        self.model = load_network(files.model, self.algo, hp.get("policy"), AgentLoadError)

    @staticmethod
    def _load_normalization(path: Path, norm_obs: bool, config: Path) -> _Statistics:
        """The statistics in ``path``, checked against the configuration's ``norm_obs``
        (``config``): statistics of another run would normalise what this agent saw raw, or
        leave raw what it saw normalised, and damaged ones give NaN actions."""
        stats = _Loaded._read_normalization(path)
        if stats.norm_obs != norm_obs:
            raise AgentLoadError(
                f"{path}: norm_obs={stats.norm_obs} but {config} says the agent was trained "
                f"with norm_obs={norm_obs}: the statistics are not this agent's"
            )
        problem = statistics_problem(stats)
        if problem is not None:
            raise AgentLoadError(f"{path}: damaged normalisation statistics: {problem}")
        return stats

    @staticmethod
    def _read_normalization(path: Path) -> _Statistics:
        """The fields inference needs of the ``VecNormalize`` pickled in ``path``, unchecked."""
        import pickle

        if not path.exists():
            raise AgentLoadError(
                f"{path}: normalisation statistics not found (the config says the agent was "
                "trained on normalised observations)"
            )
        try:
            with path.open("rb") as f:
                saved = pickle.load(f)
            # A VecNormalize saved without its env: read its fields directly (its attribute
            # lookup would ask the missing env).
            fields = vars(saved)
            return _Statistics(
                bool(fields["norm_obs"]),
                fields.get("obs_rms"),
                float(fields["epsilon"]),
                float(fields["clip_obs"]),
            )
        except Exception as e:  # pickle raises many kinds; a wrong object lacks the fields
            raise AgentLoadError(
                f"{path}: not VecNormalize statistics ({type(e).__name__}: {e})"
            ) from None

    def pipeline(self, n: int) -> Pipeline:
        """A fresh feature pipeline for ``n`` lanes."""
        steps = Pipeline.from_wrappers(self.wrappers) + self.own_steps()
        return Pipeline(steps, self.observation_box, self.action_box, n)

    def own_steps(self) -> list[Feature]:
        """The outermost steps, this agent's own: its frozen observation normalisation and its
        ``frame_stack`` (an ensemble's members share the steps inside them)."""
        steps: list[Feature] = []
        stats = self.normalization
        if stats is not None and stats.norm_obs:
            rms = stats.obs_rms
            steps.append(NormalizeObservation(rms.mean, rms.var, stats.epsilon, stats.clip_obs))
        if self.frame_stack > 1:
            steps.append(FrameStack(self.frame_stack))
        return steps


_CACHE: dict[tuple, _Loaded] = {}
#: Guards :data:`_CACHE` only, never held while an agent loads: a load may build other policies
#: (a law for :class:`~policies.learned.hint.LawHint`, an ensemble's members), and holding one
#: lock across it hung for ever whenever a load needed another agent. Two threads loading the
#: same agent at once both read it; the first to finish is kept.
_CACHE_LOCK = threading.Lock()
#: The agents this thread is loading: an agent whose loading needs itself (a cycle through
#: names) is refused, where it would recurse until the stack ran out.
_LOADING = threading.local()


def file_version(path: Path) -> tuple[int, ...] | None:
    """A file's version, told without reading it (None: nothing there): device, inode, size,
    modification and change times. The change time moves even when ``cp -p`` keeps the other."""
    try:
        st = path.stat()
    except OSError:
        return None
    return (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns)


def _loaded(files: AgentFiles) -> _Loaded:
    key = tuple(
        (str(p.resolve()), file_version(p))
        for p in (files.model, files.normalization, files.config)
    )
    with _CACHE_LOCK:
        found = _CACHE.get(key)
    if found is not None:
        return found
    loading: set[tuple] | None = getattr(_LOADING, "keys", None)
    if loading is None:
        loading = _LOADING.keys = set()
    if key in loading:
        raise AgentLoadError(
            f"{files.config}: loading this agent needs the agent itself (its view names it)"
        )
    loading.add(key)
    try:
        agent = _Loaded(files)
    finally:
        loading.discard(key)
    with _CACHE_LOCK:
        return _CACHE.setdefault(key, agent)


class PPOPolicy:
    """A trained agent as a :class:`~policies.base.Policy` (module docstring).

    :param path: a run folder, a ``model.zip`` or a checkpoint ``.zip``.
    :param name: the name in tables and logs (default: ``path`` as given).
    :raises AgentLoadError: for a missing, corrupt or mismatched file (naming it).
    """

    def __init__(self, path: str | Path, name: str | None = None) -> None:
        self.path = str(path)
        self._absolute = str(Path(path).absolute())  # not resolve(): symlinks as given
        self.name = name if name is not None else self.path.rstrip("/")
        self._agent = _loaded(agent_files(path))
        #: The platform the agent was trained on, and its action's entries (what it commands).
        self.platform: str = self._agent.platform
        self.action_names: tuple[str, ...] = self._agent.action_names
        #: The Gymnasium id of the task the agent was trained on (``"PersonFollow-v0"``, ...).
        self.env_id: str = self._agent.env_id
        files = self._agent.files
        view = self._agent.pipeline(1)
        try:
            view.start(np.zeros((1, *self._agent.observation_box.shape), np.float32))
        except ValueError as e:  # statistics of another shape
            raise AgentLoadError(
                f"{files.normalization}: does not fit the agent in {files.config} ({e})"
            ) from None
        model = self._agent.model
        # an asymmetric actor-critic's critic reads entries of its own, which inference omits
        privileged = len(getattr(model.policy, "privileged_signs", ()))
        acts_on = (model.observation_space.shape[0] - privileged,)
        if acts_on != view.observation_box.shape:
            raise AgentLoadError(
                f"{files.model}: expects observations of shape {acts_on}, "
                f"but {files.config} builds {view.observation_box.shape}; the model and "
                "the configuration are from different runs"
            )
        if model.action_space.shape != view.action_box.shape:
            raise AgentLoadError(
                f"{files.model}: acts with shape {model.action_space.shape}, but {files.config} "
                f"expects {view.action_box.shape}"
            )
        self._view: Pipeline | None = None
        self._batch: Pipeline | None = None
        self._memory: Memory | None = None  # a recurrent agent's LSTM state, per lane
        self._batch_memory: Memory | None = None
        self._started = False
        self.action_names = self._agent.action_names
        self._obs_size = self._agent.observation_box.shape[0]
        self._follows = self._agent.env_id == SPEC.env_id and self._obs_size in OBS_SIZES
        #: The reading ahead this agent reads (``{"ahead_rays": n, "ahead_half_angle_deg": a}``,
        #: its training's perception settings), or None: it reads ``[distance_m, offset_px]``.
        #: Evaluation gives it the reading ahead (:mod:`eval.rollout`); a robot must publish it.
        self.reads_ahead: dict[str, Any] | None = None
        if self._follows and self._obs_size == OBS_SIZES[1]:
            # Every setting, the defaults of those its training left at theirs.
            given = self._agent.perception or {}
            self.reads_ahead = {k: given.get(k, v) for k, v in AHEAD_SETTINGS.items()}
        #: What the agent needs of an env on top of a run's configuration (the reading ahead's
        #: settings); evaluation applies it (:mod:`eval.rollout`). The reading has draws of its
        #: own, so every other policy's episodes on the same seeds are unchanged by it.
        self.env_overrides: dict[str, Any] = (
            {"perception": dict(self.reads_ahead)} if self.reads_ahead else {}
        )

    def _rows(self, obs: np.ndarray, batch: bool) -> np.ndarray:
        """Observations as float32 rows, checked: PersonFollow's by its own rules (an agent
        trained without the reading ahead reads the first two entries of an observation that
        has it), another task's by the saved observation size."""
        obs = real_obs(obs)
        if self._follows:
            arr = validate_obs_batch(obs) if batch else validate_obs_row(obs)[None]
            if arr.shape[1] < self._obs_size:
                raise ValueError(
                    f"{self.name} reads the reading ahead ({AHEAD.name}, observation entry 2), "
                    f"but obs has {arr.shape[1]} entries: make the env with perception="
                    f"{self.reads_ahead!r}"
                )
            return arr[:, : self._obs_size].astype(np.float32)
        arr = np.asarray(obs, dtype=np.float64)
        shape = (arr.shape[0], self._obs_size) if batch and arr.ndim == 2 else (self._obs_size,)
        if arr.shape != shape or (batch and arr.ndim != 2):
            want = f"(n, {self._obs_size})" if batch else f"({self._obs_size},)"
            raise ValueError(f"obs must have shape {want}, got shape {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise ValueError("obs must be finite")
        return arr.reshape(-1, self._obs_size).astype(np.float32)

    def reset(self) -> None:
        """Start a new episode: the next :meth:`act` starts the pipeline (and a recurrent
        agent's LSTM state) afresh."""
        self._started = False

    def act(self, obs: np.ndarray) -> np.ndarray:
        """Map an observation (``[distance_m, offset_px]`` for PersonFollow) to the platform's
        action, :attr:`action_names` (``[v_mps, w_radps]`` on the differential drive),
        deterministically.

        :raises ValueError: if ``obs`` is not a finite array of real numbers
            (:func:`policies.base.real_obs`) of the agent's observation shape.
        """
        row = self._rows(obs, batch=False)
        if not self._started or self._view is None:
            self._view = self._agent.pipeline(1)
            self._memory = self._agent.model.memory(1)
            agent_obs = self._view.start(row)
            self._started = True
        else:
            agent_obs = self._view.observe(row)
        action = self._agent.model.act(agent_obs, self._memory)
        return self._view.act(action).astype(np.float32)[0]

    def reset_batch(self, n: int) -> None:
        """Start ``n`` lanes' episodes."""
        self._batch = None
        self._batch_n = n
        self._restart = np.zeros(n, dtype=bool)

    def reset_lanes(self, lanes: np.ndarray) -> None:
        """Start new episodes in the lanes flagged in ``lanes`` (bool, one per lane of
        :meth:`reset_batch`), the others' memory kept: what an auto-resetting vector env needs.
        The next :meth:`act_batch` gives a flagged lane the view of a new episode, as
        training's autoreset did (:meth:`~policies.learned.features.Pipeline.observe`)."""
        self._restart = lane_flags(
            lanes, getattr(self, "_batch_n", None), getattr(self, "_restart", None)
        )
        if self._batch is not None and self._batch_memory is not None:
            self._batch_memory.restart(self._restart)

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        """Actions ``(n, m)`` for observations ``(n, 2)``, each lane as :meth:`act` would give
        it alone (the network runs one lane at a time: module docstring)."""
        rows = self._rows(obs, batch=True)
        if getattr(self, "_batch_n", None) != len(rows):
            raise ValueError(
                f"act_batch got {len(rows)} observations: call reset_batch({len(rows)}) first"
            )
        if self._batch is None:
            self._batch = self._agent.pipeline(len(rows))
            self._batch_memory = self._agent.model.memory(len(rows))
            agent_obs = self._batch.start(rows)
        else:
            agent_obs = self._batch.observe(rows, self._restart)
        self._restart = np.zeros(len(rows), dtype=bool)
        actions = self._agent.model.act(agent_obs, self._batch_memory)
        return self._batch.act(actions).astype(np.float32)

    def __reduce__(self) -> tuple[Any, ...]:
        # From its files (no torch pickling) by the absolute path: a worker's folder may differ.
        return (PPOPolicy, (self._absolute, self.name))

    def __repr__(self) -> str:
        return f"PPOPolicy(name={self.name!r}, model={str(self._agent.files.model)!r})"


def load_agent(path: str | Path, name: str | None = None) -> PPOPolicy:
    """Build a :class:`PPOPolicy` from a run folder or a ``.zip`` (see :func:`agent_files`)."""
    return PPOPolicy(path, name)


def load_default() -> PPOPolicy:
    """The shipped agent, named ``"ppo"``."""
    return PPOPolicy(DEFAULT_AGENT, name="ppo")


def load_shipped(folder: str, name: str | None = None) -> PPOPolicy:
    """The shipped agent ``policies/agents/<folder>`` (e.g. ``"ppo_line"``), named ``name``
    (default: ``folder``)."""
    return PPOPolicy(AGENTS / folder, name=name or folder)


def shipped_name(folder: str | Path) -> tuple[str, str] | None:
    """``(name, task)`` that ``make_policy`` builds the agent in ``folder`` under, when
    ``folder`` is one of the shipped agents' (:data:`SHIPPED`); None for any other folder."""
    path = Path(folder).resolve()
    if path.parent != AGENTS.resolve():
        return None
    return SHIPPED.get(path.name)


def resolve_path(name: str) -> PPOPolicy | None:
    """Registry resolver: a name that is a path (a folder, ``*.zip``, or with a ``/``) -> agent.

    Other names are left to the registry (None), so a typo such as ``"pnn"`` still lists the
    known names, while ``"runs/typo"`` says which file is missing.
    """
    path = Path(name)
    if name.endswith(".zip") or "/" in name or path.is_dir():
        return PPOPolicy(path, name)
    return None
