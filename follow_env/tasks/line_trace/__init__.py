"""LineTrace-v0: a robot traces a black line on white tiles with a 5 x 5 grid of light sensors
(the mecanum paper's task, reference §2).

This package's modules, lowest first: :mod:`.spec` (names and units, no simulation import),
:mod:`.config` (sections and presets), :mod:`.tracks` (the courses, registered by name),
:mod:`.reward` and :mod:`.kernel` (the compiled step; the sensor grid is
:mod:`follow_env.sensors.light_grid`), :mod:`.task` (the runner's side), :mod:`.render`,
:mod:`.env` (the env classes and their manual), and the evaluation's :mod:`.steplog`.
Importing the package itself loads nothing heavy.
"""

ENV_ID = "LineTrace-v0"

ENVS = {
    ENV_ID: {
        "entry_point": "follow_env.tasks.line_trace.env:LineTraceEnv",
        "vector_entry_point": "follow_env.tasks.line_trace.env:LineTraceVectorEnv",
    }
}
"""Gymnasium ids and entry points of this task."""
