"""What a task is, in names and units only: the contract policies and the robot bridge see.

A :class:`TaskSpec` says what a task's observation holds (names, units, meaning), what its info
reports, and why its episodes end. It imports nothing from the simulation (numpy at most), so a
policy or the hardware bridge can depend on it without loading compiled kernels.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Quantity", "TaskSpec"]


@dataclass(frozen=True)
class Quantity:
    """One named entry of an observation, an action or an info dict.

    :param name: the key (units in the name where a number could be read two ways).
    :param unit: the unit (``""`` for flags and counts).
    :param doc: what it means.
    """

    name: str
    unit: str
    doc: str


@dataclass(frozen=True)
class TaskSpec:
    """A task's names, units and episode ends.

    :param name: registry name (``"person_follow"``).
    :param env_id: the Gymnasium id (``"PersonFollow-v0"``).
    :param doc: one line.
    :param observation: the observation's entries, in order.
    :param terminations: the reasons an episode ends, by code (code 0 is ``""``: not ended).
    :param info: the task's keys of the env's ``info`` dict, in order.
    :param platform_info_after: the task key after which the platform's own info keys (its
        wheels, motors) go.
    """

    name: str
    env_id: str
    doc: str
    observation: tuple[Quantity, ...]
    terminations: tuple[str, ...]
    info: tuple[Quantity, ...]
    platform_info_after: str = ""

    @property
    def observation_size(self) -> int:
        """Entries of one observation."""
        return len(self.observation)

    @property
    def observation_names(self) -> tuple[str, ...]:
        """The observation's entry names, in order."""
        return tuple(q.name for q in self.observation)

    def info_keys(self, platform_keys: tuple[str, ...] = ()) -> tuple[str, ...]:
        """The info dict's keys, in order, with a platform's keys in their place."""
        keys = [q.name for q in self.info]
        at = keys.index(self.platform_info_after) + 1 if self.platform_info_after else len(keys)
        return (*keys[:at], *platform_keys, *keys[at:])

    def reason(self, name: str) -> int:
        """The code of the termination reason ``name``."""
        return self.terminations.index(name)
