"""A live rerun view of a whole training run: ``python -m crllk.train live=serve|spawn``.

One recording stream stays open from the first iteration to the last. It is served by the
training process itself, on ``127.0.0.1:live_port`` only (a gRPC server sink that keeps up to
:data:`_SERVER_MEMORY` of the run for viewers that connect late); a viewer connects with
``rerun --bind 127.0.0.1 --connect rerun+http://127.0.0.1:<live_port>/proxy``, and
``live=spawn`` starts such a viewer. Logging only queues data for the server's threads, so
training never waits on a viewer: one that is missing, slow, stopped or gone costs nothing but
the queued data, and a live view that cannot start is a warning.

Logged on the ``iteration`` timeline: each iteration's row of ``metrics.csv`` named in
:data:`SERIES` at ``train/<column>`` (with the constraint thresholds beside J_clane and
J_coll), and the evaluation recordings of ``record_every`` forwarded whole from their files
(the map, the robot, its camera, the per-step signals), so the map and camera views show the
latest evaluation episode. :func:`live_blueprint` lays it out.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import rerun as rr
import rerun.blueprint as rrb
from rerun.chunk import RrdReader

from crllk.recording.blueprint import scene_views
from crllk.recording.viewer import VIEWER_HOST, check_port_free, free_port, start_viewer
from crllk.tasks.constraints import Constraint

LIVE_PORT = 9877
"""Default port of the live stream's server (the viewer's own default is 9876)."""
APPLICATION_ID = "crllk-train"
"""Viewers keep one layout per application: the live view's apart from recordings'."""
PREFIX = "train/"
PPO_DIAGNOSTICS = ("loss_objective", "loss_critic", "loss_cost_critic", "loss_entropy",
                   "loss_imitation")
"""PPO-Lagrangian's diagnostics: the live view's default (a learner names its own)."""
SERIES_NAMES = {"loss_objective": "policy loss", "loss_critic": "critic loss",
                "loss_cost_critic": "cost critic loss", "loss_entropy": "entropy loss",
                "loss_imitation": "imitation loss", "loss_actor": "policy loss",
                "loss_qvalue": "Q-value loss", "loss_alpha": "temperature loss",
                "frames_per_s": "frames/s"}
"""Plot names of the diagnostics that have one; any other is plotted under its column name."""
THRESHOLD = "threshold"
"""``train/<metric>/threshold`` (``train/J_clane/threshold``, ...): the constraint bounds."""


def series(constraints: Sequence[Constraint],
           diagnostics: Sequence[str] = PPO_DIAGNOSTICS) -> dict[str, str]:
    """Columns of ``metrics.csv`` logged at ``train/<column>``, with their plot names: J_R,
    each constraint's metric and multiplier, the losses among the learner's ``diagnostics``
    (:attr:`crllk.algos.base.Learner.diagnostic_names`, ``loss_*``), frames/s."""
    return {"J_R": "J_R (m)",
            **{c.metric: f"{c.metric} ({c.unit})" for c in constraints},
            **{f"lambda_{c.name}": f"λ_{c.name}" for c in constraints},
            **{name: SERIES_NAMES.get(name, name)
               for name in (*(d for d in diagnostics if d.startswith("loss_")), "frames_per_s")}}
_SERVER_MEMORY = "512MiB"
"""The server keeps at most this much of the run for viewers that connect later."""
_THRESHOLD_RGB = (160, 160, 160)


def live_url(port: int) -> str:
    """The gRPC URL a viewer connects to (``rerun --bind 127.0.0.1 --connect URL``)."""
    return f"rerun+http://{VIEWER_HOST}:{port}/proxy"


def live_blueprint(constraints: Sequence[Constraint],
                   diagnostics: Sequence[str] = PPO_DIAGNOSTICS) -> rrb.Blueprint:
    """The map, a chase view and the camera of the latest evaluation episode with its events on
    the left (:func:`crllk.recording.blueprint.scene_views`); one plot per training series on the
    right; the ``iteration`` timeline, following the newest data."""
    plots = [rrb.TimeSeriesView(origin=PREFIX + column, name=name,
                                plot_legend=rrb.PlotLegend(visible=False),
                                axis_x=rrb.TimeAxis(link="LinkToGlobal"))
             for column, name in series(constraints, diagnostics).items()]
    return rrb.Blueprint(
        rrb.Horizontal(scene_views(), rrb.Grid(*plots, grid_columns=3), column_shares=[2, 3]),
        rrb.BlueprintPanel(state="collapsed"), rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(timeline="iteration", play_state="following", state="collapsed"))


class LiveView:
    """The live stream of one training run (see the module's docstring).

    Args:
        sinks: where the stream goes (:func:`open_live` gives the server; tests a file).
        recording_id: the run's recording id.
        constraints: the task's constraints.
        thresholds: their bounds by constraint name (``{"lane": 0.5, "collision": 0.02}``).
        diagnostics: the learner's diagnostic columns (its losses), one plot each.
    """

    def __init__(self, sinks: list, recording_id: str, constraints: Sequence[Constraint],
                 thresholds: Mapping[str, float], url: str | None = None,
                 diagnostics: Sequence[str] = PPO_DIAGNOSTICS) -> None:
        self.url = url
        self.series = series(constraints, diagnostics)
        self.thresholds = {c.metric: thresholds[c.name] for c in constraints}
        self.rec = rr.RecordingStream(APPLICATION_ID, recording_id=recording_id)
        self.rec.set_sinks(*sinks)
        self.rec.send_blueprint(live_blueprint(constraints, diagnostics), make_active=True,
                                make_default=True)
        self.rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        for column, name in self.series.items():
            self.rec.log(PREFIX + column, rr.SeriesLines(names=name), static=True)
        for column in self.thresholds:
            self.rec.log(f"{PREFIX}{column}/{THRESHOLD}",
                         rr.SeriesLines(names=THRESHOLD, colors=_THRESHOLD_RGB), static=True)

    def log_iteration(self, row: Mapping[str, Any]) -> None:
        """One row of ``metrics.csv`` (its ``iteration``, the :func:`series` columns; a
        column that is NaN, such as J_R of an iteration where no episode ended, is left out)."""
        self.rec.set_time("iteration", sequence=int(row["iteration"]))
        for column in self.series:
            value = row.get(column)
            if value is not None and math.isfinite(value):
                self.rec.log(PREFIX + column, rr.Scalars(float(value)))
        for column, bound in self.thresholds.items():
            self.rec.log(f"{PREFIX}{column}/{THRESHOLD}", rr.Scalars(bound))

    def add_recording(self, path: Path) -> None:
        """Forward the chunks of an evaluation recording (``recordings/iteration_*.rrd``,
        which carry their ``iteration``) into the live stream; a file that cannot be read is
        a warning."""
        try:
            self.rec.send_chunks(RrdReader(path).stream())
        except Exception as err:  # the live view never stops training
            print(f"warning: live view: {path} not shown: {err}", file=sys.stderr, flush=True)

    def close(self) -> None:
        """Stop the stream (a server shuts down; viewers keep what they received)."""
        self.rec.disconnect()


def server_sink(port: int) -> rr.GrpcServerSink:
    """A gRPC server on ``127.0.0.1:port`` keeping up to :data:`_SERVER_MEMORY` of the run."""
    return rr.GrpcServerSink(VIEWER_HOST, port, server_memory_limit=_SERVER_MEMORY)


def open_live(mode: str, port: int, recording_id: str, constraints: Sequence[Constraint],
              thresholds: Mapping[str, float], diagnostics: Sequence[str] = PPO_DIAGNOSTICS
              ) -> tuple[LiveView | None, list[str]]:
    """The run's live view served on ``127.0.0.1:port`` (``mode`` ``"serve"``), with a native
    viewer connected to it (``"spawn"``), or None (``"none"``, or the port is taken); the
    problems are warnings for the caller to print."""
    if mode == "none":
        return None, []
    url = live_url(port)
    try:
        check_port_free(port)  # rerun's server would fail later, in its own thread
        live = LiveView([server_sink(port)], recording_id, constraints, thresholds, url,
                        diagnostics)
    except Exception as err:  # a live view never stops training
        return None, [f"live view unavailable ({VIEWER_HOST}:{port}: {err}); training goes on "
                      "without it"]
    problems = []
    if mode == "spawn":
        try:
            start_viewer(free_port(), "--connect", url)
        except RuntimeError as err:
            problems.append(f"{err}; connect a viewer with `rerun --bind {VIEWER_HOST} "
                            f"--connect {url}`")
    return live, problems


__all__ = ["APPLICATION_ID", "LIVE_PORT", "PPO_DIAGNOSTICS", "PREFIX", "THRESHOLD", "LiveView",
           "live_blueprint", "live_url", "open_live", "series", "server_sink"]
