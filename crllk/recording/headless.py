"""A headless rerun viewer driven from Python: start it, wait until a recording has loaded,
move the time cursor, take a picture once the frames settle, read what the views report.

The viewer runs with ``--headless`` (software Vulkan: Debian's ``mesa-vulkan-drivers`` and
``libvulkan1``, installed by ``scripts/install-egl.sh``) on a free port of 127.0.0.1 and is
driven with ``rerun.experimental.ViewerClient``; :mod:`crllk.recording.viewer` runs and stops
its process. :mod:`crllk.screenshots` builds its command on this.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator
from dataclasses import dataclass

from rerun.experimental import ViewerClient

from crllk.recording.viewer import VIEWER_HOST, free_port, start_viewer, stop_viewer

WINDOW_SIZE = (1600, 1000)
"""Width and height of the headless viewer's window (px)."""
START_TIMEOUT = 60.0
"""How long the headless viewer may take to listen and answer (s)."""
_START_ATTEMPTS = 3
"""Viewers started before giving up (a free port may be taken before the viewer binds it)."""
_LOAD_TIMEOUT = 60.0
"""How long a recording may take to load (s)."""
_SETTLE = 1.5
"""Wait after moving the time cursor before the first frame is compared (s)."""
_STABLE_TIMEOUT = 30.0
"""How long to wait for two consecutive frames to agree before taking the last one (s)."""
POLL = 0.5
"""Interval between polls of the viewer's state or frames (s)."""


class ScreenshotError(Exception):
    """Bad input or a viewer that does not do what it is asked."""


@dataclass(frozen=True)
class ViewProblem:
    """A warning or error a view reported (``severity``: ``warning`` or ``error``)."""

    view: str
    severity: str
    summary: str


@contextlib.contextmanager
def headless_viewer(size: tuple[int, int] = WINDOW_SIZE) -> Iterator[ViewerClient]:
    """A headless native viewer on a free port of 127.0.0.1 and a client driving it; the
    viewer and its process group are stopped on leaving, whatever happened.

    Raises:
        ScreenshotError: when no viewer starts (the last reason given).
    """
    process, reason = None, ""
    for _ in range(_START_ATTEMPTS):
        port = free_port()
        try:
            process = start_viewer(port, "--headless", "--window-size", f"{size[0]}x{size[1]}",
                                   "--hide-welcome-screen", timeout=START_TIMEOUT)
            break
        except RuntimeError as err:
            reason = str(err)
    if process is None:
        raise ScreenshotError(f"{reason} (a headless viewer needs Vulkan: "
                              "bash scripts/install-egl.sh)")
    try:
        yield _connect(port)
    finally:
        stop_viewer(process)


def _connect(port: int) -> ViewerClient:
    deadline = time.monotonic() + START_TIMEOUT
    while True:
        try:
            client = ViewerClient.connect(f"rerun+http://{VIEWER_HOST}:{port}/proxy")
            client.get_state()
            return client
        except Exception as err:  # not answering yet
            if time.monotonic() > deadline:
                raise ScreenshotError(f"the headless viewer does not answer: {err}") from None
            time.sleep(POLL)


def wait_loaded(client: ViewerClient, timeline: str, timeout: float = _LOAD_TIMEOUT) -> None:
    """Wait until the viewer loads nothing more and its recording has data on ``timeline``.

    Raises:
        ScreenshotError: naming the recording's timelines if ``timeline`` is not one of them,
            or after ``timeout`` (s).
    """
    deadline = time.monotonic() + timeout
    names: list[str] = []
    while time.monotonic() < deadline:
        state = client.get_state()
        timelines = [t for r in state.recordings for t in r.timelines]
        names = sorted({t.name for t in timelines})
        if not state.loading and any(t.name == timeline and t.end is not None
                                     for t in timelines):
            return
        if not state.loading and names and timeline not in names:
            raise ScreenshotError(f"no timeline {timeline!r} in the recording; it has "
                                  f"{', '.join(names)}")
        time.sleep(POLL)
    raise ScreenshotError(f"the recording did not load within {timeout:.0f} s "
                          f"(timelines so far: {', '.join(names) or 'none'})")


def seek(client: ViewerClient, timeline: str, time_value: float) -> None:
    """Pause the viewer at ``time_value`` of ``timeline``: seconds on a duration timeline
    (``sim_time``), a number on a sequence timeline (``step``, ``iteration``)."""
    kinds = {t.name: t.time_type for r in client.get_state().recordings for t in r.timelines}
    if kinds.get(timeline) == "duration":
        client.set_time(timeline, duration=time_value, play_state="paused")
    else:
        client.set_time(timeline, sequence=round(time_value), play_state="paused")


def view_id(client: ViewerClient, name: str) -> str:
    """The id of the visible view called ``name``.

    Raises:
        ScreenshotError: listing the views when none has that name.
    """
    views = client.get_state().views
    for view in views:
        if view.name == name and view.visible:
            return view.view_id
    raise ScreenshotError(f"no view named {name!r}; the views are "
                          f"{', '.join(repr(v.name) for v in views)}")


def settled_png(client: ViewerClient, view: str | None = None,
                timeout: float = _STABLE_TIMEOUT) -> bytes:
    """A PNG of the viewer (or of the view with id ``view``) once two consecutive frames agree
    (plots and images finished loading), or the last frame after ``timeout`` (s)."""
    time.sleep(_SETTLE)
    deadline = time.monotonic() + timeout
    previous = client.take_screenshot(view)
    while time.monotonic() < deadline:
        time.sleep(POLL)
        frame = client.take_screenshot(view)
        if frame == previous:
            return frame
        previous = frame
    return previous


def view_problems(client: ViewerClient) -> list[ViewProblem]:
    """What the visible views report failing to show."""
    return [ViewProblem(view.name, report.severity, report.summary)
            for view in client.get_state().views if view.visible for report in view.reports]


__all__ = ["POLL", "START_TIMEOUT", "WINDOW_SIZE", "ScreenshotError", "ViewProblem",
           "headless_viewer", "seek", "settled_png", "view_id", "view_problems", "wait_loaded"]
