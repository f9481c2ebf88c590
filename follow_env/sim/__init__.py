"""The task-agnostic simulation layer.

Nothing here knows about wheels, cameras or people: the compiled-code cache (:mod:`.jit`), the
counter-based random numbers and their one allocation table (:mod:`.rng`, :mod:`.streams`),
named state and parameter blocks (:mod:`.schema`), the validated configuration base
(:mod:`.config`, :mod:`.checks`), the kernel composition (:mod:`.compose`), the batched lane
runner (:mod:`.runner`), the Gymnasium / stable-baselines3 faces over any task
(:mod:`.faces`, :mod:`.sb3`), and the atomic file writes every layer and leaf uses
(:mod:`.atomic`). The layers above (world, platforms, sensors, tasks) import from
here, never the other way round.
"""
