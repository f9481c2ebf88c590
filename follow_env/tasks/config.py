"""What every task's configuration shares: a platform that may be named, and how ``gym.make``'s
keyword arguments, presets and ``--config`` texts become a configuration.

:class:`TaskConfig` is the base of a task's tree of sections (its first field is ``platform``,
whose sections are reached at the top level too, see :class:`~follow_env.sim.config.Sections`);
a platform may be given by name anywhere a section may (``"platform": "mecanum"``,
``{"platform": {"name": "mecanum", ...}}``). :func:`resolve_config` turns a task's
``gym.make`` arguments into its configuration, and :func:`config_from_text` reads a command
line's ``--config``; both are the same for every task, given its presets.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import yaml
from gymnasium import spaces

from follow_env.platforms import get_platform
from follow_env.platforms.base import Platform, PlatformConfig
from follow_env.sim.checks import (
    is_integer,
    is_real,
    load_yaml,
    out_of_range,
    utf8_problem,
    yaml_problem,
)
from follow_env.sim.config import Sections
from follow_env.tasks.spec import TaskSpec

__all__ = [
    "TaskConfig",
    "TaskPlatforms",
    "config_from_text",
    "named_platform",
    "names_platform",
    "resolve_config",
    "section_or_name",
]


@dataclass(frozen=True)
class TaskConfig(Sections):
    """Base of a task's configuration: subclasses declare ``platform`` (a
    :class:`PlatformConfig`) and an ``episode`` section with ``control_dt_s``, then their own
    sections; the platform is checked against the control period."""

    NESTED: ClassVar[str | None] = "platform"

    def __post_init__(self) -> None:
        super().__post_init__()
        self.platform.check_control_period(self.episode.control_dt_s)  # type: ignore[attr-defined]

    @property
    def control_dt_s(self) -> float:
        """The control period (s)."""
        return self.episode.control_dt_s  # type: ignore[attr-defined,no-any-return]

    @classmethod
    def from_overrides(cls, base: Any, overrides: Mapping[str, Any]) -> Any:
        """As :meth:`Sections.from_overrides`; the platform may also be named: ``"platform":
        "mecanum"``, ``"platform": {"name": "mecanum", "motor": {...}}`` (the form ``to_dict``
        writes) or ``"platform.name": "mecanum"``. A named platform replaces the current one
        where it appears, so later keys may use its sections (``{"platform": "mecanum",
        "floor": {...}}``); naming the platform the configuration already has keeps its
        settings (a preset's, such as ``ideal``'s spreads of 0)."""
        cfg, pending = base, {}
        for key, value in overrides.items():
            if not names_platform(key, value):
                pending[key] = value
                continue
            cfg = super().from_overrides(cfg, pending) if pending else cfg
            platform = named_platform(key, value, cfg.platform)
            cfg, pending = super().from_overrides(cfg, {"platform": platform}), {}
        return super().from_overrides(cfg, pending)


def names_platform(key: str, value: Any) -> bool:
    """Whether a ``platform`` override names a platform (rather than setting its sections)."""
    return (
        key == "platform.name"
        or (key == "platform" and isinstance(value, str))
        or (key == "platform" and isinstance(value, Mapping) and "name" in value)
    )


def named_platform(
    key: str, value: Any, current: PlatformConfig | None = None
) -> PlatformConfig | None:
    """The platform config a ``platform`` override names, or None if it names none: the
    platform's default configuration (without its manufacturing spread if ``current`` has
    none: ``ideal`` on any platform is every motor alike), or ``current`` when that is already
    of the named platform (a name alone must not undo a preset's settings of it), with the
    mapping's sections applied on top."""
    if not names_platform(key, value):
        return None
    name, rest = _name_and_sections(value)
    kind = get_platform(name).config
    if type(current) is kind:
        base = current
    else:
        base = kind()
        spread = current.spread() if current is not None else {}
        if spread and not any(spread.values()):
            base = base.without_spread()
    return type(base).from_overrides(base, rest) if rest else base


def _name_and_sections(value: Any) -> tuple[str, dict[str, Any]]:
    """A platform override's name (checked to be text) and its section overrides."""
    name, rest = value, {}
    if isinstance(value, Mapping):
        name, rest = value["name"], {k: v for k, v in value.items() if k != "name"}
    if not isinstance(name, str):
        raise ValueError(f"platform name {name!r} is out of range: must be a string")
    return name, rest


def resolve_config(
    cls: type[TaskConfig],
    presets: Mapping[str, TaskConfig],
    default: TaskConfig,
    config: Any = None,
    platform: str | PlatformConfig | Mapping[str, Any] | None = None,
    shorthands: Mapping[str, Any] | None = None,
    overrides: Mapping[str, Any] | None = None,
) -> Any:
    """A task's configuration from ``gym.make`` keyword arguments.

    :param cls: the task's config class. :param presets: its presets by name.
    :param default: the preset a dict of overrides applies to (and ``config=None`` means).
    :param config: a preset name, a config object, or a mapping of section overrides.
    :param platform: a platform name (its default configuration), a platform config object,
        or a mapping naming one with section overrides (``{"name": "mecanum", "drive": {"mode":
        "pid"}}``, the form ``to_dict`` writes); it is put in before a ``config`` mapping, whose
        keys may then use its sections (``{"platform.drive.mode": "pid"}``), and the platform's
        sections may still be overridden (``motor={...}``).
    :param shorthands: dotted fields set by the task's shorthand arguments, applied last (e.g.
        ``{"scenario.name": "curve"}``); ``None`` values are left out.
    :param overrides: sections (``sensor={...}``) or ``section__field=value`` pairs.
    """
    _check_platform(platform)  # refused before anything else when it names no platform
    if config is None:
        cfg = default
    elif isinstance(config, cls):
        cfg = config
    elif isinstance(config, str):
        if config not in presets:
            raise out_of_range(
                "config",
                config,
                "one of " + ", ".join(repr(p) for p in presets) + f" or {_a(cls.__name__)}",
            )
        cfg = presets[config]
    elif isinstance(config, dict):
        if platform is not None:
            named = [k for k, v in config.items() if names_platform(k, v)]
            if named:
                raise ValueError(
                    f"the platform is given twice: platform= and config[{named[0]!r}]; give one"
                )
            default, platform = cls.from_overrides(default, {"platform": platform}), None
        cfg = cls.from_overrides(default, config)
    else:
        raise out_of_range("config", config, f"a preset name, {_a(cls.__name__)} or a dict")
    if platform is not None:  # first, so that the overrides below may use its sections
        cfg = cls.from_overrides(cfg, {"platform": platform})
    flat: dict[str, Any] = {}
    for key, value in (overrides or {}).items():
        flat[key.replace("__", ".")] = value
    for key, value in (shorthands or {}).items():
        if value is not None:
            flat[key] = value
    return cls.from_overrides(cfg, flat) if flat else cfg


def section_or_name(section: str, value: Any) -> dict[str, Any]:
    """The override a task's shorthand argument (``scenario=``, ``track=``) stands for: a name
    sets the section's ``name``; a mapping or a section object is the whole section, as every
    other section may be given to ``gym.make``. For ``resolve_config``'s ``shorthands``."""
    if isinstance(value, str) or value is None or is_integer(value) or is_real(value):
        return {f"{section}.name": value}  # a number is refused there, naming the field
    return {section: value}


def _check_platform(platform: str | PlatformConfig | Mapping[str, Any] | None) -> None:
    """Refuse a ``gym.make`` ``platform=`` that is not a name, a config object or a mapping
    with a ``name``, or that names no registered platform (the config is built later, where it
    is put in: on the configuration's own platform when it names that one)."""
    if platform is None or isinstance(platform, PlatformConfig):
        return
    if not names_platform("platform", platform):
        raise out_of_range(
            "platform",
            platform,
            "a platform's name, a platform config, or a mapping with its 'name' and section "
            "overrides",
        )
    get_platform(_name_and_sections(platform)[0])


def _a(noun: str) -> str:
    return ("an " if noun[0] in "AEIOU" else "a ") + noun


def config_from_text(
    text: str, cls: type[TaskConfig], presets: Mapping[str, TaskConfig], default: TaskConfig
) -> str | dict[str, Any]:
    """A command line's ``--config``: a preset name, a JSON object of section overrides, or a
    ``.json``/``.yaml`` file holding one; checked against ``default`` and returned as the
    preset name or the overrides (what ``config=`` takes).

    :raises ValueError: naming the file or the text and what is wrong (unreadable, not
        YAML/JSON, not a mapping, or a config value out of range).
    """
    if text in presets:
        return text
    path = Path(text)
    if path.suffix.lower() in (".json", ".yaml", ".yml"):
        try:
            overrides = load_yaml(path.read_text(encoding="utf-8"))
        except OSError as exc:
            raise ValueError(f"cannot read {path}: {exc.strerror}") from None
        except UnicodeDecodeError as exc:
            raise ValueError(f"{path} is {utf8_problem(exc)}") from None
        except yaml.YAMLError as exc:
            raise ValueError(f"{path} is not valid YAML/JSON: {yaml_problem(exc)}") from None
        where = str(path)
    else:
        try:
            overrides = json.loads(text, object_pairs_hook=_unique_keys)
        except _KeyTwiceError as exc:
            raise ValueError(f"{text!r} is not a valid JSON object: {exc}") from None
        except RecursionError:  # json's recursion, thousands of levels deep
            raise ValueError(
                f"the JSON object given ({len(text)} characters) is nested too deeply"
            ) from None
        except json.JSONDecodeError as exc:
            if text.lstrip().startswith("{"):  # meant as JSON: say what is wrong with it
                raise ValueError(
                    f"{text!r} is not a valid JSON object: {exc.msg} at character {exc.pos + 1}"
                ) from None
            kind = "a folder" if path.is_dir() else "not a preset"
            raise ValueError(
                f"{text!r} is {kind}: give a preset ({', '.join(sorted(presets))}), a JSON "
                "object, or a .json/.yaml file"
            ) from None
        where = "the JSON object"
    if not isinstance(overrides, dict):
        raise ValueError(f"{where} must be a mapping of config sections")
    try:
        cls.from_overrides(default, overrides)
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None
    return overrides


class _KeyTwiceError(ValueError):
    """A JSON object that gives a key twice (``json`` keeps the last without a word)."""


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """``json.loads``'s ``object_pairs_hook``: an object's keys, each once, as the YAML files'
    (:func:`follow_env.sim.checks.load_yaml`)."""
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise _KeyTwiceError(f"found the key {key!r} twice")
        out[key] = value
    return out


class TaskPlatforms:
    """What every task model answers the same way about its platform (a mixin of the task
    classes, which set ``spec``)."""

    spec: TaskSpec

    def __reduce__(self) -> str:
        """Copied and pickled by reference to its module's ``TASK`` (a task model is one
        object per task: the runner's cached record types and columns are keyed on it)."""
        return "TASK"

    def platform_of(self, cfg: Any) -> Platform:
        """The registered platform of ``cfg.platform``."""
        return get_platform(cfg.platform.NAME)

    def info_keys(self, platform: Platform) -> tuple[str, ...]:
        """Every key of the ``info`` dict on ``platform``."""
        return self.spec.info_keys(tuple(key for key, *_ in platform.info))

    def action_space(self, cfg: Any, platform: Platform) -> spaces.Box:
        """The platform's action, float32, bounded by what it can do."""
        top = platform.action_high(cfg).astype(np.float32)
        return spaces.Box(-top, top, dtype=np.float32)
