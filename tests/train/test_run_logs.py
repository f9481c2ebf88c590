"""train/run.py: the held-out evaluation log is read through one checked reader."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from train.run import EVALUATIONS, read_evaluations


def _save(run: Path, **arrays: np.ndarray) -> None:
    np.savez(run / EVALUATIONS, **arrays)


def test_a_log_is_read_and_no_log_is_none(tmp_path: Path) -> None:
    assert read_evaluations(tmp_path) is None
    _save(
        tmp_path,
        timesteps=np.array([300, 600]),
        results=np.array([[1.0, 2.0], [3.0, 4.0]]),
        ep_lengths=np.array([[5, 6], [7, 8]]),
    )
    log = read_evaluations(tmp_path)
    assert log is not None
    assert log.timesteps.tolist() == [300, 600]
    assert log.results[-1].tolist() == [3.0, 4.0]


def test_a_log_without_evaluations_reads_as_empty(tmp_path: Path) -> None:
    # np.savez of empty lists gives 1-D arrays: no shape for the results to agree with
    empty = np.asarray([])
    _save(tmp_path, timesteps=empty.astype(np.int64), results=empty, ep_lengths=empty)
    log = read_evaluations(tmp_path)
    assert log is not None
    assert (len(log.timesteps), log.results.shape) == (0, (0, 0))


@pytest.mark.parametrize(
    ("arrays", "reason"),
    [
        (
            {"timesteps": [300, 600], "results": [[1.0, 2.0]], "ep_lengths": [[5, 6]]},
            "they do not agree",
        ),
        ({"timesteps": [300], "results": [[1.0, 2.0]]}, "no array 'ep_lengths'"),
        ({"timesteps": [0.5], "results": [[1.0]], "ep_lengths": [[5]]}, "they do not agree"),
    ],
)
def test_a_log_whose_arrays_do_not_fit_is_named(
    tmp_path: Path, arrays: dict[str, list], reason: str
) -> None:
    _save(tmp_path, **{k: np.asarray(v) for k, v in arrays.items()})
    with pytest.raises(ValueError, match="not a readable held-out evaluation log") as caught:
        read_evaluations(tmp_path)
    assert str(caught.value).startswith(f"{tmp_path / EVALUATIONS}: ")
    assert reason in str(caught.value)


@pytest.mark.parametrize("data", [b"", b"PK\x03\x04", b"not a zip at all"])
def test_a_damaged_file_is_named_in_one_line(tmp_path: Path, data: bytes) -> None:
    (tmp_path / EVALUATIONS).write_bytes(data)
    with pytest.raises(ValueError, match="not a readable held-out evaluation log") as caught:
        read_evaluations(tmp_path)
    assert "\n" not in str(caught.value)
