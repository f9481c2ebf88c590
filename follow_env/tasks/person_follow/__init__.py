"""PersonFollow-v0: a robot follows a walking person using only an RGB-D camera (reference §1).

This package's modules, lowest first: :mod:`.spec` (names and units, no simulation import),
:mod:`.config` (sections and presets), :mod:`.people` and :mod:`.scenarios` (who walks where),
:mod:`.perception`, :mod:`.reward` and :mod:`.kernel` (the compiled step), :mod:`.task` (the
runner's side), :mod:`.render`, :mod:`.env` (the env classes and their manual), and the
evaluation's :mod:`.steplog` and :mod:`.metrics`. Importing the package itself loads nothing
heavy.
"""

ENV_ID = "PersonFollow-v0"

ENVS = {
    ENV_ID: {
        "entry_point": "follow_env.tasks.person_follow.env:PersonFollowEnv",
        "vector_entry_point": "follow_env.tasks.person_follow.env:PersonFollowVectorEnv",
    }
}
"""Gymnasium ids and entry points of this task."""
