"""``render_mode="human"``: a window showing the env's frames, with pygame as Gymnasium's own
envs do. pygame is imported only when a window is opened; without it, or without a display,
the error says what to do."""

from __future__ import annotations

import os
import sys
import time
from typing import Any

import numpy as np

__all__ = ["Window"]


def _has_display() -> bool:
    if os.environ.get("SDL_VIDEODRIVER"):  # e.g. "dummy" for tests, "wayland", "x11"
        return True
    if sys.platform in ("win32", "darwin"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


class Window:
    """A window of ``width`` x ``height`` px titled ``title`` that shows RGB frames."""

    def __init__(self, title: str, width: int, height: int) -> None:
        os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
        try:
            import pygame
        except ImportError:
            raise RuntimeError(
                'render_mode="human" needs pygame: pip install pygame (or use '
                'render_mode="rgb_array")'
            ) from None
        if not _has_display():
            raise RuntimeError(
                'render_mode="human" needs a display, and none was found (DISPLAY is not '
                'set): use render_mode="rgb_array", or run under a desktop or Xvfb'
            )
        self._pg: Any = pygame
        pygame.display.init()
        pygame.display.set_caption(title)
        self._screen = pygame.display.set_mode((width, height))
        self._last = 0.0

    def show(self, frame: np.ndarray, fps: float) -> None:
        """Draw ``frame`` (H x W x 3 uint8 RGB) and keep to ``fps`` frames a second."""
        pg = self._pg
        pg.event.pump()  # keep the window responsive
        surface = pg.surfarray.make_surface(np.ascontiguousarray(frame.swapaxes(0, 1)))
        self._screen.blit(surface, (0, 0))
        pg.display.flip()
        wait = self._last + 1.0 / fps - time.monotonic()
        if wait > 0.0:
            time.sleep(wait)
        self._last = time.monotonic()

    def close(self) -> None:
        """Close the window."""
        self._pg.display.quit()
