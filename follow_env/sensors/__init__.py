"""Sensors: the camera, the person detector (with its tracker and delay line), depth.

Each module holds a sensor's config section, its per-lane parameter and state blocks, its
per-episode randomisation and the compiled models a task's frame calls. Sensors import the sim
and world layers (and a platform's body record), never a task.
"""
