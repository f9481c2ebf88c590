"""Reproductions of the sources' hardware experiments in simulation, one module per platform.

:mod:`follow_env.experiments.mecanum`: the mecanum paper's three experiments (reference §2).
This layer sits above the tasks: it may use every layer below (a config of the person-following
task supplies the episode settings), and nothing in the simulation imports it.
"""
