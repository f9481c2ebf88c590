"""The run folder: its layout, atomic saves, checkpoints, the held-out evaluation log.

::

    runs/ppo-<timestamp>/   (recurrent_ppo-<timestamp>, sac-<timestamp>: --algo)
      config.yaml           the resolved configuration: algorithm, options, hyperparameters,
                            env spaces
      model.zip             the final agent (SB3 PPO or SAC, sb3-contrib RecurrentPPO)
      vecnormalize.pkl      its observation normalisation statistics (VecNormalize)
      MODEL_CARD.md         command, seed, versions, training time, scores
      learning_curve.png    held-out evaluation return and training return over steps
      evaluations.npz       the EvalCallback log (timesteps, results, ep_lengths)
      sessions.json         one entry per training session (a resume starts a new one), kept
                            up to date at every checkpoint, so a killed session still counts
      checkpoints/          ppo_<steps>_steps.zip + ppo_vecnormalize_<steps>_steps.pkl (the
                            prefix is the algorithm's); SAC's newest checkpoint also has its
                            replay buffer, sac_replay_buffer_<steps>_steps.pkl
      logs/                 progress-<first step>.csv per session, tb/ (TensorBoard events)

Every file is written to a temporary name beside it and renamed into place, so a run killed at
any moment leaves complete files only; a checkpoint's statistics are written before its model,
so a model file in ``checkpoints/`` always has its statistics (and an off-policy model its replay
buffer, which only the newest checkpoint keeps: it can be large). Nothing else is written: the
held-out evaluation keeps SB3's own log in memory (earlier versions kept it in a
``.eval-scratch-*`` folder, which a kill left behind; :func:`remove_stale_scratch` clears those).
"""

from __future__ import annotations

import io
import json
import re
import shutil
import time
import zipfile
from collections.abc import Iterator
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import yaml
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import CheckpointCallback, EvalCallback
from stable_baselines3.common.vec_env import VecNormalize

import policies.learned.ppo as _ppo
from follow_env.sim.atomic import atomic_path, atomic_write_text
from follow_env.sim.checks import load_yaml, utf8_problem, yaml_problem

__all__ = [
    "CHECKPOINT_PREFIX",
    "CONFIG",
    "EVALUATIONS",
    "MODEL",
    "NORMALIZATION",
    "AtomicCheckpointCallback",
    "Evaluations",
    "HeldOutEvalCallback",
    "SessionLog",
    "config_text",
    "new_run_dir",
    "newest_checkpoint",
    "not_written_early",
    "read_config",
    "read_evaluations",
    "read_sessions",
    "remove_stale_scratch",
    "replay_buffer_file",
    "save_model",
    "save_normalization",
    "write_config",
    "write_sessions",
]

# An agent's files as the loader names them (one definition: a run folder is an agent's).
CONFIG, MODEL, NORMALIZATION = _ppo.CONFIG, _ppo.MODEL, _ppo.NORMALIZATION
CARD = "MODEL_CARD.md"
CURVE = "learning_curve.png"
EVALUATIONS = "evaluations.npz"
SESSIONS = "sessions.json"
CHECKPOINTS = "checkpoints"
LOGS = "logs"
CHECKPOINT_PREFIX = "ppo"  # PPO's; each algorithm's checkpoints start with its name


def run_dir_names(root: str | Path = "runs", prefix: str = "ppo") -> Iterator[Path]:
    """The names a new run folder may take, in order: ``root/<prefix>-<timestamp>[-k]``.

    :raises FileExistsError: once the 1000 names of this second are all taken.
    """
    stamp = f"{prefix}-{datetime.now():%Y%m%d-%H%M%S}"
    for k in range(1000):
        yield Path(root) / (stamp if k == 0 else f"{stamp}-{k}")
    raise FileExistsError(f"{root}: no free run folder name for {stamp}")


def new_run_dir(root: str | Path = "runs", prefix: str = "ppo") -> Path:
    """Create and return a new run folder ``root/<prefix>-<timestamp>[-k]``."""
    Path(root).mkdir(parents=True, exist_ok=True)
    names = run_dir_names(root, prefix)
    while True:
        path = next(names)  # FileExistsError once every name is taken
        try:
            path.mkdir()
        except FileExistsError:
            continue
        return path


def config_text(config: dict[str, Any]) -> str:
    """The text of a ``config.yaml`` holding ``config``."""
    return yaml.safe_dump(config, sort_keys=False, default_flow_style=None, width=100)


def write_config(run: Path, config: dict[str, Any]) -> Path:
    """Write the resolved configuration as ``config.yaml`` (atomically)."""
    return atomic_write_text(run / CONFIG, config_text(config))


def read_config(path: str | Path) -> dict[str, Any]:
    """Read a run's ``config.yaml`` (a path to the file or to its folder).

    :raises ValueError: naming the file if it is missing or not a mapping.
    """
    path = Path(path)
    if path.is_dir():
        path = path / CONFIG
    try:
        config = load_yaml(path.read_text(encoding="utf-8"))
    except OSError as e:
        raise ValueError(f"{path}: cannot read the run configuration: {e.strerror or e}") from None
    except UnicodeDecodeError as e:
        raise ValueError(f"{path}: the run configuration is {utf8_problem(e)}") from None
    except yaml.YAMLError as e:
        raise ValueError(
            f"{path}: the run configuration is not valid YAML: {yaml_problem(e)}"
        ) from None
    if not isinstance(config, dict) or "hyperparams" not in config:
        raise ValueError(f"{path}: not a follow-train run configuration (no 'hyperparams')")
    return config


def read_sessions(run: Path) -> list[dict[str, Any]]:
    """The training sessions recorded so far (empty for a new run).

    :raises ValueError: naming the file if it is not a JSON list.
    """
    path = run / SESSIONS
    if not path.exists():
        return []
    try:
        sessions = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ValueError(f"{path}: cannot read the training sessions: {e}") from None
    if not isinstance(sessions, list) or not all(isinstance(s, dict) for s in sessions):
        raise ValueError(f"{path}: not a list of training sessions")
    return sessions


class Evaluations(NamedTuple):
    """The held-out evaluation log, ``evaluations.npz``: after ``timesteps[i]`` env steps the
    agent scored ``results[i, j]`` (env return) in ``ep_lengths[i, j]`` steps on episode ``j``."""

    timesteps: np.ndarray
    results: np.ndarray
    ep_lengths: np.ndarray


def read_evaluations(run: Path) -> Evaluations | None:
    """The run's held-out evaluation log, checked (None if it has none yet).

    :raises ValueError: naming the file if it is not a readable log whose arrays agree (a
        truncated or foreign file: ``np.load`` would raise from deep in numpy or zipfile).
    """
    path = run / EVALUATIONS
    if not path.exists():
        return None
    what = f"{path}: not a readable held-out evaluation log"
    try:
        with np.load(path, allow_pickle=False) as log:
            found = {k: np.asarray(log[k]) for k in Evaluations._fields if k in log.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as e:
        raise ValueError(f"{what} ({type(e).__name__}: {e})") from None
    missing = [k for k in Evaluations._fields if k not in found]
    if missing:
        raise ValueError(f"{what} (no array {missing[0]!r})")
    arrays = Evaluations(**found)
    steps, results, lengths = arrays
    if steps.size == results.size == lengths.size == 0:  # no evaluation yet: no shapes to agree
        return Evaluations(np.zeros(0, np.int64), np.zeros((0, 0)), np.zeros((0, 0), np.int64))
    if not (
        steps.ndim == 1
        and results.ndim == 2
        and results.shape == lengths.shape
        and len(results) == len(steps)
        and np.issubdtype(steps.dtype, np.integer)
        and np.issubdtype(results.dtype, np.floating)
    ):
        raise ValueError(
            f"{what} (timesteps {steps.shape} {steps.dtype}, results {results.shape} "
            f"{results.dtype}, ep_lengths {lengths.shape}: they do not agree)"
        )
    return arrays


def write_sessions(run: Path, sessions: list[dict[str, Any]]) -> None:
    """Record the training sessions (atomically)."""
    atomic_write_text(run / SESSIONS, json.dumps(sessions, indent=2) + "\n")


class SessionLog:
    """This session's entry in ``sessions.json``, rewritten as training goes.

    The entry is written when learning starts (``status`` "running") and updated at every
    checkpoint, so a session that is killed still counts in the card with the steps and time
    up to its last checkpoint, which is where a resume continues. :meth:`close` records how
    it ended. A "running" entry found by the next session was killed, and is marked so.

    Entry keys: ``command``, ``started_utc``, ``finished_utc`` (None until it ends),
    ``status`` ("running", "finished", "interrupted", "failed", "killed"), ``first_step``,
    ``last_step`` (the steps a resume keeps: the last checkpoint's, or the final model's),
    ``wall_s`` (learning time [s] up to ``last_step``; an interrupted or failed session's whole
    time), ``env_steps_per_s``, ``threads``, ``mkl_intel_paths`` (the option given) and
    ``mkl_code_path`` (the code path MKL reported: 0 its generic one, None without MKL).

    :param run: the run folder.
    :param command: the command line of this session.
    :param first_step: env steps the session starts from.
    :param threads: torch threads.
    :param mkl_intel_paths: whether ``--mkl-intel-paths`` was given (:mod:`train.mkl_paths`).
    :param mkl_code_path: :func:`train.mkl_paths.mkl_code_path` in the training process.
    """

    def __init__(
        self,
        run: Path,
        command: str,
        first_step: int,
        threads: int,
        mkl_intel_paths: bool = False,
        mkl_code_path: int | None = None,
    ) -> None:
        self.run = run
        self.sessions = read_sessions(run)
        for session in self.sessions:
            if session.get("status") == "running":
                session["status"] = "killed"
        self.entry: dict[str, Any] = {
            "command": command,
            "started_utc": datetime.now(UTC).isoformat(timespec="seconds"),
            "finished_utc": None,
            "status": "running",
            "first_step": first_step,
            "last_step": first_step,
            "wall_s": 0.0,
            "env_steps_per_s": None,
            "threads": threads,
            "mkl_intel_paths": mkl_intel_paths,
            "mkl_code_path": mkl_code_path,
        }
        self.sessions.append(self.entry)
        self._started = time.perf_counter()
        write_sessions(run, self.sessions)

    def _record(self, last_step: int, steps_done: int) -> None:
        wall_s = time.perf_counter() - self._started
        self.entry["last_step"] = last_step
        self.entry["wall_s"] = round(wall_s, 1)
        self.entry["env_steps_per_s"] = round(steps_done / wall_s) if steps_done > 0 else None

    def checkpoint(self, step: int) -> None:
        """A checkpoint at ``step`` env steps was written: record the session up to it."""
        self._record(step, step - self.entry["first_step"])
        write_sessions(self.run, self.sessions)

    def close(self, status: str, last_step: int, steps_done: int) -> None:
        """Record how the session ended.

        :param status: "finished", "interrupted" or "failed".
        :param last_step: the steps a resume keeps (the final model's, or the last
            checkpoint's when the session did not finish).
        :param steps_done: env steps this session trained, kept or not (for the rate).
        """
        self._record(last_step, steps_done)
        self.entry["status"] = status
        self.entry["finished_utc"] = datetime.now(UTC).isoformat(timespec="seconds")
        write_sessions(self.run, self.sessions)


def remove_stale_scratch(run: Path) -> list[Path]:
    """Remove the ``.eval-scratch-*`` folders earlier versions left in ``run`` when killed.

    Only folders holding nothing but SB3's ``evaluations.npz`` are removed (that is all such a
    folder ever held); anything else is left alone.

    :returns: the folders removed.
    """
    removed = []
    for folder in sorted(run.glob(".eval-scratch-*")):
        if folder.is_dir() and not folder.is_symlink():
            contents = [p.name for p in folder.iterdir()]
            if set(contents) <= {"evaluations.npz"}:
                shutil.rmtree(folder)
                removed.append(folder)
    return removed


#: What a run writes before its first checkpoint (:func:`not_written_early`): files in its
#: folder, and the files a folder of it holds (paths relative to that folder).
_EARLY_FILES = (CONFIG, SESSIONS, EVALUATIONS)
_EARLY_INSIDE = {
    LOGS: re.compile(r"progress-[0-9]+\.csv|tb|tb/events\.out\.tfevents\..+"),
    # an unfinished checkpoint: its statistics and replay buffer are written before the model
    CHECKPOINTS: re.compile(r"[a-z_]+_(vecnormalize|replay_buffer)_[0-9]+_steps\.pkl"),
}
#: The name of an atomic write's temporary file, as :mod:`follow_env.sim.atomic` makes it
#: (``mkstemp`` with its ``_affixes``): ".", at most 32 characters of the target's stem, ".",
#: ``mkstemp``'s 8 random characters, ".tmp" and the target's suffix if at most 16 long; or
#: the probe ``check_writable`` makes and removes at once (``.write-check.`` and 8 characters,
#: after ``x`` padding when a long name is probed).
_TEMPORARY = re.compile(
    r"\.[^/]{1,32}\.[a-z0-9_]{8}\.tmp(\.[^./]{1,15})?|\.write-check\.x*[a-z0-9_]{8}"
)


def not_written_early(run: Path) -> str | None:
    """The first entry of ``run`` (a path relative to it) that a run does not write before its
    first checkpoint, or None: what may be deleted to start a run killed that early again is
    its config, session and held-out logs, SB3's ``logs/`` (progress CSVs, TensorBoard
    events), the files of a checkpoint it did not finish, and the temporary files of atomic
    writes cut short (:data:`_TEMPORARY`); never a link, another hidden file, or a hidden
    folder (a ``.git``, a notebook's ``.ipynb_checkpoints``)."""
    for path in sorted(run.iterdir()):
        if path.is_symlink():
            return path.name
        if _temporary(path) or (path.name in _EARLY_FILES and path.is_file()):
            continue
        pattern = _EARLY_INSIDE.get(path.name)
        if pattern is None or not path.is_dir():
            return path.name
        for child in sorted(path.rglob("*")):  # a folder before what it holds
            relative = child.relative_to(path).as_posix()
            if _temporary(child):
                continue
            kind = child.is_dir() if relative == "tb" else child.is_file()
            if child.is_symlink() or not (kind and pattern.fullmatch(relative)):
                return f"{path.name}/{relative}"
    return None


def _temporary(path: Path) -> bool:
    """``path`` is a regular file named as an atomic write's temporary file."""
    return bool(_TEMPORARY.fullmatch(path.name)) and path.is_file() and not path.is_symlink()


def save_model(model: BaseAlgorithm, path: Path) -> Path:
    """``model.save`` to ``path`` atomically (the temporary name keeps the ``.zip`` suffix)."""
    with atomic_path(path) as tmp:
        model.save(tmp)
    return path


def save_normalization(venv: VecNormalize | None, path: Path) -> Path | None:
    """``VecNormalize.save`` to ``path`` atomically; nothing when there is no normalisation."""
    if venv is None:
        return None
    with atomic_path(path) as tmp:
        venv.save(str(tmp))
    return path


def newest_checkpoint(run: Path, prefix: str = CHECKPOINT_PREFIX) -> tuple[int, Path, Path] | None:
    """``(steps, model zip, statistics pkl)`` of the newest complete checkpoint, or None.

    A checkpoint is complete when its model file exists (statistics and a replay buffer are
    written first); the statistics path is returned even if the config does not normalise (it
    then does not exist).

    :param prefix: the checkpoints' prefix, the run's algorithm (``ppo``, ``sac`` ...).
    """
    folder = run / CHECKPOINTS
    pattern = re.compile(rf"^{re.escape(prefix)}_(\d+)_steps\.zip$")
    found = []
    for path in folder.glob(f"{prefix}_*_steps.zip") if folder.is_dir() else []:
        match = pattern.match(path.name)
        if match:
            found.append((int(match.group(1)), path))
    if not found:
        return None
    steps, model = max(found)
    return steps, model, folder / f"{prefix}_vecnormalize_{steps}_steps.pkl"


def replay_buffer_file(checkpoint: Path) -> Path:
    """The replay buffer saved with the checkpoint model ``<prefix>_<steps>_steps.zip``
    (``<prefix>_replay_buffer_<steps>_steps.pkl``; on-policy runs have none)."""
    prefix, steps, _ = checkpoint.name.rsplit("_", 2)
    return checkpoint.with_name(f"{prefix}_replay_buffer_{steps}_steps.pkl")


class AtomicCheckpointCallback(CheckpointCallback):
    """SB3's ``CheckpointCallback`` (model + VecNormalize, and an off-policy model's replay
    buffer), each file written atomically.

    The replay buffer of the newest checkpoint only is kept (older ones are removed once the
    new checkpoint is complete), so a resumed SAC run learns on from the transitions it had.

    :param save_freq_steps: env steps between checkpoints (all lanes counted).
    :param run: the run folder; checkpoints go to ``run/checkpoints``.
    :param n_envs: lanes, to turn env steps into callback calls.
    :param session: told of every checkpoint written (``sessions.json``), if given.
    :param prefix: the checkpoint files' prefix (the algorithm's name).
    """

    def __init__(
        self,
        save_freq_steps: int,
        run: Path,
        n_envs: int,
        session: SessionLog | None = None,
        *,
        prefix: str = CHECKPOINT_PREFIX,
    ) -> None:
        super().__init__(
            save_freq=max(save_freq_steps // n_envs, 1),
            save_path=str(run / CHECKPOINTS),
            name_prefix=prefix,
            save_vecnormalize=True,
        )
        self.session = session

    def _on_step(self) -> bool:
        if self.n_calls % self.save_freq == 0:
            self.save()
        return True

    def save(self) -> None:
        """Write the checkpoint of the model as it is now (also called once training ends, so
        that a finished run's newest checkpoint is its final state: a later ``--resume``
        continues from there, not from an older checkpoint)."""
        self.num_timesteps = self.model.num_timesteps
        model = Path(self._checkpoint_path(extension="zip"))
        if model.is_file():
            return  # written at this very step already
        save_normalization(
            self.model.get_vec_normalize_env(),
            Path(self._checkpoint_path("vecnormalize_", extension="pkl")),
        )
        buffer = getattr(self.model, "replay_buffer", None)
        if buffer is not None:
            with atomic_path(replay_buffer_file(model)) as tmp:
                self.model.save_replay_buffer(tmp)
        save_model(self.model, model)
        if buffer is not None:
            for old in model.parent.glob(f"{self.name_prefix}_replay_buffer_*_steps.pkl"):
                if old != replay_buffer_file(model):
                    old.unlink(missing_ok=True)
        if self.session is not None:
            self.session.checkpoint(self.num_timesteps)


class HeldOutEvalCallback(EvalCallback):
    """SB3's ``EvalCallback`` on the same held-out episodes every time, logged atomically.

    Before each evaluation the eval env is seeded with ``eval_seed`` (lane ``j`` gets
    ``eval_seed + j``), so the curve compares the agent with itself on identical episodes.
    ``evaluations.npz`` in the run folder gets the log, atomically; a resumed run continues the
    existing log. SB3 saves its own copy with ``np.savez`` to ``log_path`` after every
    evaluation, not atomically; here ``log_path`` is an in-memory file, so nothing but
    ``evaluations.npz`` reaches the disk and a kill leaves nothing behind.

    :param eval_env: built like the training env (:func:`train.envs.agent_env`, mode "eval").
    :param run: the run folder.
    :param eval_seed: the first held-out seed.
    :param eval_freq_steps: env steps between evaluations (all training lanes counted).
    :param n_envs: training lanes, to turn env steps into callback calls.
    :param start_step: the env steps the session starts from (a resume's checkpoint).
    """

    def __init__(
        self,
        eval_env: Any,
        run: Path,
        eval_seed: int,
        eval_freq_steps: int,
        n_envs: int,
        *,
        start_step: int = 0,
    ) -> None:
        super().__init__(
            eval_env,
            n_eval_episodes=eval_env.num_envs,
            eval_freq=max(eval_freq_steps // n_envs, 1),
            log_path=None,
            deterministic=True,
            verbose=0,
        )
        # Not None, so that SB3 keeps the per-episode results; np.savez accepts a file object.
        self.log_path: Any = io.BytesIO()
        self.run = run
        self.eval_seed = eval_seed
        previous = read_evaluations(run)
        if previous is not None:
            # A resume goes on from the checkpoint at start_step: evaluations the earlier
            # session made after it are of steps now trained again, and go.
            kept = previous.timesteps <= start_step
            self.evaluations_timesteps = previous.timesteps[kept].tolist()
            self.evaluations_results = previous.results[kept].tolist()
            self.evaluations_length = previous.ep_lengths[kept].tolist()

    def _init_callback(self) -> None:
        log_path, self.log_path = self.log_path, None  # SB3 would make a folder for a path
        super()._init_callback()
        self.log_path = log_path

    def _on_step(self) -> bool:
        due = self.eval_freq > 0 and self.n_calls % self.eval_freq == 0
        if due:
            self.eval_env.seed(self.eval_seed)
            self.log_path = io.BytesIO()  # a fresh one: SB3's copy is not kept
        keep_going = super()._on_step()
        if due:
            self.write_log()
        return keep_going

    def write_log(self) -> None:
        """Write ``evaluations.npz`` (atomically) from the evaluations so far."""
        with atomic_path(self.run / EVALUATIONS) as tmp:
            np.savez(
                tmp,
                timesteps=np.asarray(self.evaluations_timesteps, dtype=np.int64),
                results=np.asarray(self.evaluations_results, dtype=np.float64),
                ep_lengths=np.asarray(self.evaluations_length, dtype=np.int64),
            )
