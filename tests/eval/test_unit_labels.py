"""How messages name an evaluation's work unit: by its policy's label, scenario and seeds
(``pn:tuned on straight, seeds 0-19``), not by a trimmed ``repr`` of the tuple it is sent as."""

from __future__ import annotations

import os
import re
import signal
import socket
import sys
from pathlib import Path

import pytest

from eval import provenance
from eval.cli import main
from eval.rollout import _run_task, rollout
from eval.units import Work, seeds_text
from execution import Backend, WorkerLostError


@pytest.mark.parametrize(
    ("seeds", "text"),
    [
        ([7], "seed 7"),
        (range(20), "seeds 0-19"),
        ([3, 5, 6, 7, 8], "seeds 3, 5-8"),
        ([2**256 - 2, 2**256 - 1], f"seeds {2**256 - 2}-{2**256 - 1}"),
        ([0, 2, 4, 6, 8, 9], "6 seeds 0, 2, 4, ..., 8-9"),  # the middle ranges elided
    ],
)
def test_seeds_are_named_as_ranges(seeds: list[int], text: str) -> None:
    assert seeds_text(list(seeds)) == text


def test_a_rollout_names_each_unit_by_policy_scenario_and_seeds(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    rollout_module = sys.modules["eval.rollout"]  # `eval.rollout` is also the function's name
    real = rollout_module.execute
    named: list[str] = []

    def naming(fn: object, units: list, *args: object, **kwargs: object) -> object:
        describe = kwargs.get("describe")
        named.extend(describe(u) if describe is not None else repr(u) for u in units)
        return real(fn, units, *args, **kwargs)

    monkeypatch.setattr(rollout_module, "execute", naming)
    rollout(["pn", "pn@mecanum"], ["straight", "curve"], range(4), workers=1, chunk=2)
    assert named == [
        "pn:tuned on straight, seeds 0-1",
        "pn:tuned on straight, seeds 2-3",
        "pn:tuned on curve, seeds 0-1",
        "pn:tuned on curve, seeds 2-3",
        "pn:tuned@mecanum on straight, seeds 0-1",
        "pn:tuned@mecanum on straight, seeds 2-3",
        "pn:tuned@mecanum on curve, seeds 0-1",
        "pn:tuned@mecanum on curve, seeds 2-3",
    ]


def test_an_error_a_units_worker_raised_names_the_unit_by_its_label(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """It named it ``(('pn', 'straight', (5, 6, 7, 8, 9, 10, ...), None, None, ...))``."""
    # the driver's code digest another than its spawned workers': each refuses its unit
    monkeypatch.setitem(provenance._RUNNING, provenance.ROLLOUT_PACKAGES, "f" * 64)
    grid = ["--policies", "pn", "--scenarios", "straight", "--episodes", "40", "--seed", "5"]
    argv = ["run", *grid, "--out", str(tmp_path / "run"), "--workers", "2", "--no-logs"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert "runs other code than the driver" in err
    host = re.escape(socket.gethostname())
    unit = r"\(in work unit (\d) \(pn:tuned on straight, seeds (\d+)-(\d+)\) on host "
    found = re.search(unit + host + ", process ", err)
    assert found is not None, err
    k, first, last = map(int, found.groups())  # 4 units of 10 seeds: unit k's seeds
    assert (first, last) == (5 + 10 * k, 14 + 10 * k)


def _dies(work: object) -> None:  # run by a spawned worker, imported by name
    os.kill(os.getpid(), signal.SIGKILL)


def test_a_unit_whose_worker_keeps_dying_is_named_by_its_label(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(sys.modules["eval.rollout"], "_run_task", _dies)
    with pytest.raises(WorkerLostError) as lost:
        rollout(["pn"], ["crowd"], [7], backend=Backend("local", workers=2, max_retries=0))
    assert str(lost.value).startswith("unit 0 (pn:tuned on crowd, seed 7): its worker process died")


def _fails_under_perfect_sensing(work: Work) -> object:  # run by a spawned worker, by name
    """The plain grid's units run (its config is the preset's name); the ideal grid's, whose
    config is the perfectly sensed one, raise."""
    if not isinstance(work.config, str):
        raise ValueError("this unit refuses perfect sensing")
    return _run_task(work)


def test_a_unit_failing_in_the_ideal_grid_is_named_with_its_suffix(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """It was named ``pn:tuned on straight, ...``: as the plain grid's unit, which had run."""
    monkeypatch.setattr(sys.modules["eval.rollout"], "_run_task", _fails_under_perfect_sensing)
    grid = ["--policies", "pn", "--scenarios", "straight", "--episodes", "2", "--ideal-baseline"]
    argv = ["run", *grid, "--out", str(tmp_path / "run"), "--workers", "2", "--no-logs"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert "this unit refuses perfect sensing" in err
    found = re.search(r"\(in work unit (\d) \(pn:tuned\+ideal on straight, seed (\d)\) on ", err)
    assert found is not None, err
    assert found.group(1) == found.group(2)  # 2 units of one seed each: unit k runs seed k
    assert not (tmp_path / "run").exists()
    # the plain grid's two units had run (and are kept to resume): the failure was the ideal's
    assert len(list((tmp_path / ".run.units").glob("unit-*.pkl"))) == 2
