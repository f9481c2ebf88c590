"""The install: the project's packages are found from any folder a user's script runs in."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

PACKAGES = ("follow_env", "policies", "eval", "train", "bridge", "execution")


def test_folders_named_as_the_packages_where_a_script_runs_do_not_hide_them(tmp_path: Path) -> None:
    # A project of the user's own with an eval/ or policies/ folder (follow-train --export
    # policies/agents/... makes one): in setuptools' default editable mode Python's own search
    # took the empty folder for the package, and `from policies import make_policy` failed.
    for name in PACKAGES:
        (tmp_path / name).mkdir()
    code = (
        "from policies import make_policy; from eval import rollout; import train.ppo, "
        "bridge, execution, follow_env; print(make_policy('pn').name)"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, (
        f"{done.stderr.strip().splitlines()[-1:]}: install the project as the Makefile does "
        "(pip install -e . --config-settings editable_mode=compat)"
    )
    assert done.stdout.strip() == "pn:tuned"
