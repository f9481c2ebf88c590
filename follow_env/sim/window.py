"""``render_mode="human"``: a window showing the env's frames, with pygame as Gymnasium's own
envs do. pygame is imported only when a window is opened, and it picks its video driver as it
does for them: without a display (no ``DISPLAY``, ``WAYLAND_DISPLAY`` or ``SDL_VIDEODRIVER``)
it draws offscreen, with a one-time warning that nothing is shown, so Gymnasium's ``check_env``
passes on a headless machine as it does for CartPole. Without pygame, or where its display
cannot be set up at all, the error says what to do."""

from __future__ import annotations

import os
import sys
import time
import warnings
from typing import Any

import numpy as np

__all__ = ["Window"]

_HIDDEN_DRIVERS = ("offscreen", "dummy")
"""SDL video drivers that draw into memory: a window on them is never seen."""

_warned_hidden = False


def _visible_display_expected() -> bool:
    """Whether the environment names a display (or a driver) a window could be seen on."""
    if os.environ.get("SDL_VIDEODRIVER"):  # chosen by the user, e.g. "dummy" for tests
        return True
    if sys.platform in ("win32", "darwin"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def _warn_if_hidden(driver: str) -> None:
    """Warn once a process when pygame fell back to a driver no one can see (no display),
    unless that driver was asked for (``SDL_VIDEODRIVER``)."""
    global _warned_hidden
    if _warned_hidden or driver not in _HIDDEN_DRIVERS or _visible_display_expected():
        return
    _warned_hidden = True
    warnings.warn(
        f'render_mode="human": no display was found (DISPLAY is not set), so pygame draws the '
        f"window offscreen (SDL driver {driver!r}) and nothing is shown; use "
        'render_mode="rgb_array" for frames, or run under a desktop or Xvfb',
        RuntimeWarning,
        stacklevel=4,
    )


class Window:
    """A window of ``width`` x ``height`` px titled ``title`` that shows RGB frames.

    :raises RuntimeError: without pygame, or when pygame cannot set up its display (say, an
        ``SDL_VIDEODRIVER`` that does not exist).
    """

    def __init__(self, title: str, width: int, height: int) -> None:
        os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
        try:
            import pygame
        except ImportError:
            raise RuntimeError(
                'render_mode="human" needs pygame: pip install pygame (or use '
                'render_mode="rgb_array")'
            ) from None
        self._pg: Any = pygame
        try:
            pygame.display.init()
            pygame.display.set_caption(title)
            self._screen = pygame.display.set_mode((width, height))
        except pygame.error as err:
            pygame.display.quit()
            driver = os.environ.get("SDL_VIDEODRIVER")
            raise RuntimeError(
                f'render_mode="human" could not open a pygame window ({err}; SDL_VIDEODRIVER='
                f'{driver!r}): use render_mode="rgb_array", or run under a desktop or Xvfb'
            ) from err
        _warn_if_hidden(pygame.display.get_driver())
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
