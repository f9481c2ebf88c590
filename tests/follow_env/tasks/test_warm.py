"""follow_env/tasks/warm.py: every (task, platform) kernel compiled ahead of time."""

from __future__ import annotations

import pytest

from follow_env.platforms import available_platforms
from follow_env.tasks.warm import compile_pair, main, pairs


def test_every_tasks_ids_meet_every_platform_person_follow_first() -> None:
    got = pairs()
    ids = list(dict.fromkeys(env_id for env_id, _ in got))
    assert ids == ["PersonFollow-v0", "LineTrace-v0"]
    assert len(got) == len(ids) * len(available_platforms())


def test_a_pair_is_made_and_stepped() -> None:
    env_id, platform, seconds, status = compile_pair(("PersonFollow-v0", "diff_drive"))
    assert (env_id, platform, status) == ("PersonFollow-v0", "diff_drive", "ready")
    assert seconds > 0.0


def test_a_bad_worker_count_is_one_line_and_status_2(capsys: pytest.CaptureFixture) -> None:
    assert main(["--workers", "0"]) == 2
    assert "--workers 0 is out of range" in capsys.readouterr().err
