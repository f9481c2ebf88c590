"""The live web monitor: a FastAPI app that streams the robot's state and takes mode changes.

* :class:`~bridge.monitor.hub.MonitorHub`: the thread-safe meeting point of whatever drives
  the robot (the runner, or the simulator with ``--sim``) and the web clients;
* :func:`~bridge.monitor.app.create_app`: the FastAPI app (a static page and a WebSocket);
* :func:`~bridge.monitor.app.serve`: uvicorn in a background thread;
* :class:`~bridge.monitor.sim.SimDriver`: the simulator driven live, for ``--sim``.
"""

from bridge.monitor.hub import MODES, MonitorHub

__all__ = ["MODES", "MonitorHub"]
