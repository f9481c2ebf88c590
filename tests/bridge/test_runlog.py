"""bridge/runlog: the step log's last resort never raises, and its folder is decided up front."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from bridge.runlog import save_rows

from .conftest import ROOT

# A process out of file descriptors (as idle connections to the monitor can leave it) saves
# its log at the end of the session: nothing can be written, and saying so must not raise.
_EXHAUSTED = """
import json, os, resource, sys
from pathlib import Path
from bridge.runlog import save_rows

if sys.argv[2] == "before":  # as the runner decides it
    from bridge.runlog import spare_folder

    spare = spare_folder()
else:
    spare = None
_, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
resource.setrlimit(resource.RLIMIT_NOFILE, (64, hard))
held = []
try:
    while True:
        held.append(os.open(os.devnull, os.O_RDONLY))
except OSError:
    pass
try:
    rows = [{"policy": "pn", "step": 0, "time_s": 0.0}]
    args = (rows, Path(sys.argv[1])) if spare is None else (rows, Path(sys.argv[1]), spare)
    where, why = save_rows(*args)
    result = {"where": where and str(where), "why": why}
except BaseException as exc:
    result = {"raised": f"{type(exc).__name__}: {exc}"}
for fd in held:
    os.close(fd)
print(json.dumps(result))
"""


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX file-descriptor limits")
@pytest.mark.parametrize("decided", ["before", "at the end"])
def test_saving_with_no_file_descriptor_left_says_the_log_is_lost_and_does_not_raise(
    decided: str, tmp_path: Path
) -> None:
    log = tmp_path / "run.csv"
    done = subprocess.run(
        [sys.executable, "-c", _EXHAUSTED, str(log), decided],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    assert "raised" not in result, result["raised"]
    assert result["where"] is None
    why = f"--log {log}: the step log could not be written (cannot write to {tmp_path}: Too many "
    why += "open files)"
    if decided == "before":
        why += f", nor in {tempfile.gettempdir()} (Too many open files): lost"
    else:
        why += ", nor could a temporary folder be found to save it in: lost"
    assert result["why"] == why
    assert list(tmp_path.iterdir()) == []  # nothing half-written


def test_the_spare_file_goes_to_the_folder_given(tmp_path: Path) -> None:
    spare = tmp_path / "spare"
    spare.mkdir()
    where, why = save_rows([{"step": 0, "time_s": 0.0}], tmp_path / "gone" / "run.csv", spare)
    assert where is not None
    assert where.parent == spare
    assert why.endswith(f"; saved to {where} instead")
    assert where.read_text() == "step,time_s\n0,0\n"


def test_the_runner_saves_its_spare_log_in_the_folder_found_before_the_session(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # The temporary folder is found when the runner is made: at the end of a session the
    # process may have no file descriptor left to find it with (finding it creates a file).
    from bridge import SerialLink
    from bridge.perception import Replay
    from bridge.runlog import spare_folder
    from bridge.runner import Runner, RunnerConfig
    from policies import make_policy

    before, after = tmp_path / "before", tmp_path / "after"
    before.mkdir()
    after.mkdir()
    replay = tmp_path / "obs.csv"
    replay.write_text("time_s,obs_distance_m,obs_offset_px\n0,1.0,0\n0.1,1.02,3\n0.2,1.05,5\n")
    usb = tmp_path / "usb"
    usb.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(before))
    assert spare_folder() == before
    with SerialLink("loop://", "reference") as link:
        runner = Runner(
            link,
            make_policy("pn"),
            Replay(replay),
            config=RunnerConfig(duration_s=1.0),
            log=usb / "run.csv",
        )
        monkeypatch.setattr(tempfile, "tempdir", str(after))  # found again now: elsewhere
        shutil.rmtree(usb)  # the stick is pulled out during the session
        result = runner.run()
    assert result.log is not None
    assert result.log.parent == before
    assert os.listdir(after) == []
    assert f"saved to {result.log} instead" in result.log_error
