"""policies/registry.py: policies by name."""

from dataclasses import fields

import numpy as np
import pytest

from policies import (
    GSMPN_THESIS,
    GSMPN_TUNED,
    MPN_THESIS,
    MPN_TUNED,
    PN,
    PN_THESIS,
    PN_TUNED,
    PolicyRegistry,
    available_policies,
    make_policy,
)

LAWS = ("pn", "mpn", "gsmpn", "gsmpn-listing", "gsmpn-equation")
PRESETS = ("thesis", "tuned")


def obs(distance_m: float, offset_px: float, policy: object = None) -> np.ndarray:
    """An observation; for an agent that reads the reading ahead, with nothing near ahead."""
    ahead = [10.0] if getattr(policy, "reads_ahead", None) else []
    return np.array([distance_m, offset_px, *ahead], dtype=np.float32)


def test_every_law_and_law_preset_name_is_available() -> None:
    expected = {*LAWS, *(f"{law}:{preset}" for law in LAWS for preset in PRESETS)}
    assert expected <= set(available_policies("person_follow"))


def test_available_policies_are_sorted() -> None:
    assert available_policies() == sorted(available_policies())


@pytest.mark.parametrize("name", available_policies("person_follow"))
def test_every_available_name_builds_a_working_policy(name: str) -> None:
    policy = make_policy(name)
    policy.reset()
    assert np.all(np.isfinite(policy.act(obs(2.0, 30.0, policy))))


@pytest.mark.parametrize("law", LAWS)
def test_bare_law_name_builds_the_tuned_preset(law: str) -> None:
    policy = make_policy(law)
    assert policy.name == f"{law}:tuned"
    assert policy.params == make_policy(f"{law}:tuned").params  # type: ignore[attr-defined]


@pytest.mark.parametrize(
    ("name", "params"),
    [
        ("pn:thesis", PN_THESIS),
        ("pn:tuned", PN_TUNED),
        ("mpn:thesis", MPN_THESIS),
        ("mpn:tuned", MPN_TUNED),
        ("gsmpn:thesis", GSMPN_THESIS),
        ("gsmpn:tuned", GSMPN_TUNED),
    ],
)
def test_law_preset_name_builds_that_preset(name: str, params: object) -> None:
    policy = make_policy(name)
    assert policy.name == name
    assert policy.params == params  # type: ignore[attr-defined]


@pytest.mark.parametrize("variant", ["listing", "equation"])
@pytest.mark.parametrize("preset", PRESETS)
def test_gsmpn_variant_preset_differs_from_default_only_in_variant(
    variant: str, preset: str
) -> None:
    default = make_policy(f"gsmpn:{preset}").params  # type: ignore[attr-defined]
    other = make_policy(f"gsmpn-{variant}:{preset}").params  # type: ignore[attr-defined]
    differing = {
        f.name for f in fields(default) if getattr(default, f.name) != getattr(other, f.name)
    }
    assert differing == {"variant"}
    assert other.variant == variant


def test_thesis_laws_differ_on_a_moving_offset() -> None:
    # rate = (22 - 20) / 0.1 = 20 px/s, slow enough that GS-MPN's gain is not yet saturated
    turn_rates = set()
    for law in LAWS:
        policy = make_policy(f"{law}:thesis")
        policy.act(obs(2.0, 20.0))
        turn_rates.add(float(policy.act(obs(2.0, 22.0))[1]))
    assert len(turn_rates) == len(LAWS)


def test_each_call_builds_a_fresh_policy() -> None:
    first, second = make_policy("mpn"), make_policy("mpn")
    assert first is not second
    first.act(obs(2.0, -300.0))  # memory in one must not leak into the other
    np.testing.assert_array_equal(
        second.act(obs(2.0, 20.0)), make_policy("mpn").act(obs(2.0, 20.0))
    )


def test_unknown_name_error_lists_the_known_names() -> None:
    with pytest.raises(ValueError, match="unknown policy 'lqr'") as error:
        make_policy("lqr")
    for name in available_policies("person_follow"):
        assert name in str(error.value)


def test_an_empty_or_non_text_name_and_an_unknown_task_are_refused() -> None:
    with pytest.raises(ValueError, match=r"the policy name is empty; known names: .*pn:thesis"):
        make_policy("")  # not a model path in the current folder
    with pytest.raises(TypeError, match="a policy name is text"):
        make_policy(None)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"task='nope' is out of range: must be one of \["):
        make_policy("pn", "nope")


def test_registered_factory_is_built_by_name() -> None:
    registry = PolicyRegistry()
    registry.register("straight", lambda: PN(PN_THESIS, name="straight"))
    assert registry.make("straight").name == "straight"
    assert registry.names() == ["straight"]


def test_registering_a_taken_name_is_rejected() -> None:
    registry = PolicyRegistry()
    registry.register("pn", PN)
    with pytest.raises(ValueError, match="already registered"):
        registry.register("pn", PN)


@pytest.mark.parametrize("name", ["", "my law", "x@mecanum"])
def test_empty_spaced_or_platform_name_is_rejected(name: str) -> None:
    # "x@mecanum" could never be asked for: NAME@PLATFORM runs NAME on that platform
    with pytest.raises(ValueError, match="without whitespace and without '@'"):
        PolicyRegistry().register(name, PN)


@pytest.mark.parametrize(
    ("name", "factory", "message"),
    [
        (5, PN, "a policy name is text"),  # an AttributeError once
        ("nofactory", None, "the factory for 'nofactory' must be callable"),
    ],
)
def test_a_name_or_factory_that_cannot_serve_is_rejected(
    name: object, factory: object, message: str
) -> None:
    registry = PolicyRegistry()
    with pytest.raises(TypeError, match=message):
        registry.register(name, factory)  # type: ignore[arg-type]
    assert registry.names() == []


def test_an_unknown_task_is_rejected_when_registering_and_listing() -> None:
    registry = PolicyRegistry()
    with pytest.raises(ValueError, match=r"task='no_such_task' is out of range: must be one of"):
        registry.register("x", PN, task="no_such_task")
    with pytest.raises(ValueError, match=r"task='bogus' is out of range"):
        available_policies("bogus")  # [] once, while make_policy refused the same task


def test_register_law_adds_bare_and_preset_names() -> None:
    registry = PolicyRegistry()
    registry.register_law("pn", PN, {"thesis": PN_THESIS, "tuned": PN_TUNED})
    assert registry.names() == ["pn", "pn:thesis", "pn:tuned"]
    assert registry.make("pn").name == "pn:tuned"


def test_register_law_without_the_default_preset_is_rejected() -> None:
    with pytest.raises(ValueError, match="no preset 'tuned'"):
        PolicyRegistry().register_law("pn", PN, {"thesis": PN_THESIS})


def test_resolver_builds_names_that_are_not_registered() -> None:
    # The hook a model path ("runs/x/model.zip") will use.
    registry = PolicyRegistry()
    registry.register_resolver(
        lambda name: PN(PN_THESIS, name=name) if name.endswith(".zip") else None
    )
    assert registry.make("runs/x/model.zip").name == "runs/x/model.zip"


def test_name_no_resolver_accepts_is_unknown() -> None:
    registry = PolicyRegistry()
    registry.register_resolver(lambda name: None)
    with pytest.raises(ValueError, match=r"unknown policy 'x\.zip'.*registered resolver"):
        registry.make("x.zip")


def test_factory_returning_a_non_policy_is_a_type_error() -> None:
    registry = PolicyRegistry()
    registry.register("broken", lambda: 42)  # type: ignore[arg-type, return-value]
    with pytest.raises(TypeError, match="no Policy"):
        registry.make("broken")


def test_policies_are_listed_by_the_task_they_read() -> None:
    from policies import policy_task

    line = available_policies("line_trace")
    assert {"coordinate", "coordinate:literal", "pid", "ppo"} <= set(line)
    # only the shipped agent's name is both tasks' (each task's own agent)
    assert set(line) & set(available_policies("person_follow")) == {"ppo"}
    assert policy_task("pid") == "line_trace"
    assert policy_task("pn") == "person_follow"
    assert policy_task("ppo") == "person_follow"  # a name of both: PersonFollow's unless told


def test_a_name_of_two_tasks_builds_the_asked_tasks_policy() -> None:
    registry = PolicyRegistry()
    registry.register("agent", lambda: PN(PN_THESIS, name="follow"))
    registry.register("agent", lambda: PN(PN_TUNED, name="line"), task="line_trace")
    assert registry.make("agent").name == "follow"
    assert registry.make("agent", "person_follow").name == "follow"
    assert registry.make("agent", "line_trace").name == "line"
    assert registry.names("line_trace") == registry.names("person_follow") == ["agent"]
    with pytest.raises(ValueError, match="already registered for line_trace"):
        registry.register("agent", PN, task="line_trace")


def test_a_name_of_one_task_is_that_tasks_whatever_task_is_asked() -> None:
    registry = PolicyRegistry()
    registry.register("line-law", lambda: PN(PN_THESIS, name="line-law"), task="line_trace")
    assert registry.make("line-law").name == "line-law"
    assert registry.make("line-law", "person_follow").name == "line-law"


def test_a_bare_line_follower_name_means_its_tuned_preset() -> None:
    assert make_policy("coordinate").name == "coordinate:tuned"
    assert make_policy("pid").name == "pid:tuned"
    assert {"coordinate:signed", "pid:hand"} <= set(available_policies("line_trace"))


def test_every_shipped_agent_is_built_by_its_name_from_its_own_folder() -> None:
    from policies.learned.ensemble import ENSEMBLE
    from policies.learned.ppo import AGENTS, SHIPPED, shipped_name

    agents = [p for p in AGENTS.iterdir() if (p / "model.zip").is_file()]
    ensembles = [p for p in AGENTS.iterdir() if (p / ENSEMBLE).is_file()]
    assert ensembles  # ppo_ensemble: an agent's folder may hold an ensemble of agents
    assert sorted(p.name for p in agents + ensembles) == sorted(SHIPPED)
    for folder, (name, task) in SHIPPED.items():
        assert make_policy(name, task).path == str(AGENTS / folder)
        assert shipped_name(AGENTS / folder) == (name, task)
        assert shipped_name(AGENTS.parent / folder) is None  # the same name elsewhere
