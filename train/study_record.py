"""A study's record, ``study.json``: what the study is, and a command's claim on its folder.

``follow-train --seeds`` (:mod:`train.seeds`) writes the study's settings (:func:`study_settings`:
every option that decides what its seeds train, with the defaults filled in) and the digest of
the sources that train them (:data:`CODE`) when it makes the study, and checks them whenever it
comes back (:func:`claim`): other settings pointed at the same folder are refused, and a seed
trains on a study only with the code that started it.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

# read where the evaluation reads it too (follow-eval aggregate), which never imports training
from eval.aggregate_inputs import STUDY, read_study
from eval.provenance import ROLLOUT_PACKAGES, SHORT
from follow_env.sim.atomic import atomic_write_text
from train.algos import DEFAULT_ALGO, algo
from train.config import ConfigError, sole_section
from train.options import DEFAULT_ENV_CONFIG, Args, absolute_compare_with, base_seed
from train.study_lock import StudyLock

__all__ = ["CODE", "STUDY", "TRAINING_PACKAGES", "claim", "read_study", "study_settings"]

#: The packages whose sources decide what a seed trains: the env, the policies, the evaluation
#: (the held-out scores and the model card's comparison) and the training.
TRAINING_PACKAGES = (*ROLLOUT_PACKAGES, "train")
#: ``study.json``'s key for the sources digest of :data:`TRAINING_PACKAGES`.
CODE = "code"


#: Options that are no part of what a study is: where it goes and how fast, not what is
#: trained (a resume may lengthen it); threads and MKL's code paths change the weights as the
#: CPU does, which is not kept either.
NOT_THE_STUDY = (
    "out", "resume", "export", "force", "progress", "threads", "mkl_intel_paths", "n_timesteps"
)  # fmt: skip


def study_settings(args: Args, seeds: Sequence[int]) -> dict[str, Any]:
    """What a study is, as ``study.json`` keeps it (paths as text, the seeds as a list)."""
    out: dict[str, Any] = {"seeds": list(seeds)}
    for f in dataclasses.fields(args):
        if f.name in NOT_THE_STUDY:
            continue
        value = getattr(args, f.name)
        out[f.name] = str(value) if isinstance(value, Path) else value
    # The defaults as the run fills them in, so that leaving an option out or giving its
    # default is the same study; PPO studies keep no "algo" (as before there was a choice).
    learner = algo(args.algo or DEFAULT_ALGO)
    # The preset and seed as the run fills them in (a study from an agent has its own already).
    out["env_config"] = args.env_config or DEFAULT_ENV_CONFIG
    # (in a study from an agent without --seed, each seed's own, from its agent: None here)
    derived = args.seed is None and args.trained_agent is not None
    out["seed"] = None if derived else base_seed(args)
    own = args.trained_agent is not None and args.hyperparams is None  # the agent's own
    out["hyperparams"] = None if own else str(args.hyperparams or learner.hyperparams)
    # An agent by its path as this folder reads it: the same command run from another folder
    # names another agent (or none), and is another study; one moved away since is still this.
    out["compare_with"] = absolute_compare_with(args.compare_with, missing=True)
    if args.env_id is None and not own:  # the file's only section, as the run fills it in
        with contextlib.suppress(ConfigError):  # the seeds' own checks name the file
            out["env_id"] = sole_section(out["hyperparams"])
    if learner.name == DEFAULT_ALGO:
        del out["algo"]
    else:
        out["algo"] = learner.name
    return json.loads(json.dumps(out))


def claim(
    study: Path, settings: dict[str, Any], code: str, lock: StudyLock, *, training: bool
) -> None:
    """Write ``study.json``, or check that the folder's is this study's and, if a seed is to
    train (``training``), that the study's seeds trained with this ``code``; the folder is held
    (``lock``) before it is written, whether this command made it or another one meanwhile."""
    lock.take()
    path = study / STUDY
    had = read_study(study)
    if had is not None:
        # an option kept in files written while it counted (mkl_intel_paths, briefly)
        had = {k: v for k, v in had.items() if k not in NOT_THE_STUDY}
        if had.get("env_id") is None:  # written before the default was filled in
            had = {**had, "env_id": settings.get("env_id")}
        if isinstance(had.get("compare_with"), str):  # kept as typed before: read from here
            had = {**had, "compare_with": absolute_compare_with(had["compare_with"], missing=True)}
        changed = sorted(
            k
            for k in settings.keys() | had.keys()
            if k not in ("seeds", CODE) and had.get(k) != settings.get(k)
        )
        if changed:
            raise ValueError(
                f"{study} holds another study (its {STUDY} differs in {', '.join(changed)}); "
                "give another --out, or the same options to resume it"
            )
        if training and had.get(CODE) != code:
            raise ValueError(other_code(study, had.get(CODE), code))
        had["seeds"] = sorted(set(had.get("seeds", [])) | set(settings["seeds"]))
        atomic_write_text(path, json.dumps(had, indent=1) + "\n")
        return
    if study.exists() and any(study.iterdir()):
        raise ValueError(f"--out {study} already exists and is not an empty folder or a study")
    study.mkdir(parents=True, exist_ok=True)
    lock.take()
    atomic_write_text(path, json.dumps(settings | {CODE: code}, indent=1) + "\n")


def other_code(study: Path, had: Any, code: str) -> str:
    """Why a seed may not train in ``study`` with ``code``: one line, and what to do."""
    sources = f"{', '.join(TRAINING_PACKAGES)} sources"
    if not isinstance(had, str):
        return (
            f"{study / STUDY} records no code (the study was made before studies recorded it), "
            "so whether its seeds trained with this code cannot be checked, and a study's "
            "seeds differ in their seed only: give another --out, or, if this code trained "
            f'them, add "{CODE}": "{code}" (the SHA-256 of the {sources}) to {study / STUDY}'
        )
    return (
        f"{study}: the code changed since the study started (the SHA-256 of its {sources} "
        f"was {had[:SHORT]}, is now {code[:SHORT]}), and a study's seeds differ in their seed "
        "only: run it with the code it started with, or give another --out"
    )
