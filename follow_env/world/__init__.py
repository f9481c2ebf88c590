"""The world: geometry of walls and obstacles, line of sight, and T-RRT path planning.

Imports only the sim layer. People appear here only as records with ``x``, ``y`` (and ``th``)
fields, whatever task they belong to.
"""
