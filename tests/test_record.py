"""Rerun recordings: written from real rollouts, read back with ``rerun.chunk.RrdReader`` and
checked against an unrecorded replay; failures of the file and of the viewer."""

from __future__ import annotations

import math
import re
import socket
from pathlib import Path

import numpy as np
import pytest
import torch
from rerun.chunk import RrdReader
from torchrl.envs.utils import ExplorationType, set_exploration_type, step_mdp

import crllk
from crllk.analysis.recording_picture import (
    draw_recording,
    positions,
    scalars,
    series,
    static_value,
)
from crllk.envs.episodes import EpisodeStats
from crllk.errors import RecordingError
from crllk.maps import markings
from crllk.recording import blueprint as layout
from crllk.recording import sinks
from crllk.recording.entities import ACTION_ENTITY_PATHS, entity_paths
from crllk.recording.recorder import read_recording, record_episodes
from crllk.rl.models import ModelConfig, make_actor
from crllk.rl.rollout import run_episodes
from crllk.sim import constants as C
from crllk.tasks.constraints import BUILTIN
from crllk.tasks.follower import FollowerPolicy
from crllk.tasks.lane_keeping import state_feature_names

CONSTRAINTS = (BUILTIN["lane"], BUILTIN["collision"])

HORIZON = 30
EPISODES = 2
NUM_ENVS = 2
SEED = 3
MULTIPLIERS = {"lane": 0.25, "collision": 2.5}


def _env(num_envs: int = NUM_ENVS):
    return crllk.make_env("small_loop", num_envs=num_envs, observation="state",
                          action="discrete", seed=SEED, overrides={"horizon": HORIZON})


def _actor(env):
    """An untrained discrete actor; deterministic, it plays the same actions every time."""
    torch.manual_seed(0)
    return make_actor("state", env.observation_spec["state"].shape[1:], "discrete",
                      env.action_spec, ModelConfig(), state_feature_names(env.config))


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """Two 30-step episodes of sub-environment 0 of a 2-env batch, recorded at iteration 7."""
    env = _env()
    actor = _actor(env)
    path = tmp_path_factory.mktemp("rec") / "runs" / "x.rrd"  # the directory is created
    report = record_episodes(env, actor, EPISODES, path, iteration=7, multipliers=MULTIPLIERS,
                             recording_id="run-0")
    env.close()
    return report, read_recording(path), actor


def _replay_costs(actor) -> dict[str, list[float]]:
    """Sub-environment 0's per-step costs of the same rollout, played without recording."""
    env = _env()
    costs: dict[str, list[float]] = {"cost_lane": [], "cost_collision": []}
    td, done = env.reset(), 0
    with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
        while done < EPISODES:
            stepped = env.step(actor(td))
            for key, values in costs.items():
                values.append(float(stepped["next", key][0]))
            done += int(stepped["next", "done"][0])
            td = env.maybe_reset(step_mdp(stepped))
    env.close()
    return costs


def test_recording_holds_every_entity_and_one_pose_per_step(recorded):
    report, chunks, _ = recorded
    expected = {*entity_paths(CONSTRAINTS), *ACTION_ENTITY_PATHS["discrete"], "lagrange/lane",
                "lagrange/collision"}
    assert expected <= set(chunks), expected - set(chunks)
    assert report.steps == EPISODES * HORIZON and report.episodes == EPISODES
    assert report.warnings == () and report.logging_seconds > 0
    poses = positions(chunks)
    assert poses.steps.tolist() == list(range(1, report.steps + 1))  # one row per step
    assert sorted(set(poses.episodes.tolist())) == list(range(EPISODES))
    assert np.allclose(np.diff(poses.times), 1 / 30)
    assert len(series(chunks["world/robot/camera/image"], "Image:buffer").values) == report.steps
    iterations = {v for b in chunks["world/robot"] for v in b.column("iteration").to_pylist()}
    assert iterations == {7}
    assert scalars(chunks, "lagrange/collision").values == [2.5] * report.steps
    reader = RrdReader(report.path)
    assert [r.recording_id for r in reader.recordings()] == ["run-0"]  # merges across files
    assert reader.blueprints()  # the layout travels with the file


def test_camera_pinhole_is_in_pixels_of_the_image(recorded):
    """Read back, the pinhole's resolution is the image's [width, height] (px) and its focal
    length gives the MuJoCo camera's vertical field of view over the image's height."""
    _, chunks, _ = recorded
    env = _env(1)
    camera = env.config.camera
    fovy = math.radians(float(env.physics[0].named.model.cam_fovy[C.CAMERA]))
    env.close()
    pinhole = chunks["world/robot/camera"]
    assert static_value(pinhole, "Pinhole:resolution") == [[camera.width, camera.height]]
    columns = static_value(pinhole, "Pinhole:image_from_camera")[0]  # column-major
    matrix = np.asarray(columns).reshape(3, 3).T
    assert matrix[0, 0] == pytest.approx(matrix[1, 1])  # square pixels
    assert 2 * math.atan(0.5 * camera.height / matrix[1, 1]) == pytest.approx(fovy)
    assert matrix[:2, 2].tolist() == pytest.approx([camera.width / 2, camera.height / 2])
    frame = series(chunks["world/robot/camera/image"], "Image:format").values[0][0]
    assert (frame["width"], frame["height"]) == (camera.width, camera.height)


def test_robot_is_labelled_and_coloured_apart_from_the_objects(recorded):
    _, chunks, _ = recorded
    footprint = chunks["world/robot/footprint"]
    assert static_value(footprint, "Boxes3D:labels") == ["robot"]
    object_colours = set(static_value(chunks["world/map/objects"], "Boxes3D:colors"))
    assert not set(static_value(footprint, "Boxes3D:colors")) & object_colours
    assert static_value(chunks["world/robot/heading"], "Arrows3D:vectors")[0][0] > 0  # forward


def _views(container) -> list:
    """The views of a blueprint container, depth first."""
    if hasattr(container, "class_identifier"):
        return [container]
    return [view for item in container.contents for view in _views(item)]


def test_blueprint_gives_every_series_its_own_plot_and_a_chase_view():
    blueprint = layout.make_blueprint("continuous", CONSTRAINTS, ["lane", "collision"])
    views = _views(blueprint.root_container)
    plots = [v.origin for v in views if v.class_identifier == "TimeSeries"]
    assert sorted(plots) == sorted(
        ["reward/progress", "cost/lane", "cost/collision", "lane_pose/lateral",
         "lane_pose/heading_error", "action/velocity", "action/steering", "lagrange/lane",
         "lagrange/collision", "episode/distance", "episode/lane", "episode/collision",
         "episode/length"])
    chase = [v for v in views if v.class_identifier == "3D" and v.origin == "world/robot"]
    assert len(chase) == 1  # the eye rides in the robot's frame
    assert {"TextLog", "Dataframe", "2D"} <= {v.class_identifier for v in views}


def test_episode_plot_ranges_keep_points_off_the_edges():
    stats = [EpisodeStats(0, -0.5, {"lane": 0.2, "collision": 1.0}, 48, False),
             EpisodeStats(0, 2.0, {"lane": 0.0, "collision": 0.0}, 150, True)]
    ranges = layout.episode_ranges(stats)
    assert ranges["episode/distance"] == pytest.approx((-0.6, 2.4))
    assert ranges["episode/length"] == pytest.approx((0.0, 180.0))
    assert layout.episode_ranges([EpisodeStats(0, 0.0, {"collision": 0.0}, 0, True)])[
        "episode/collision"] == (0.0, 1.0)


def test_recording_logs_episode_boundaries_and_statistics(recorded):
    report, chunks, _ = recorded
    texts = [t[0] for t in series(chunks["events"], "TextLog:text").values]
    assert [t.split(" ", 3)[2] for t in texts] == ["starts", "ends", "starts", "ends"]
    assert "ends (time limit) after 30 steps" in texts[1]
    lengths = scalars(chunks, "episode/length")
    assert lengths.values == [HORIZON] * EPISODES
    assert scalars(chunks, "episode/lane").values == pytest.approx(
        [s.costs["lane"] for s in report.episode_stats])


def test_logged_costs_equal_an_unrecorded_replay(recorded):
    """Step by step against a replay; episode by episode against run_episodes (episode k of
    an N-env evaluation runs in sub-environment k mod N, so sub-env 0 plays 0, 2, ...)."""
    report, chunks, actor = recorded
    replay = _replay_costs(actor)
    assert scalars(chunks, "cost/lane").values == replay["cost_lane"]
    assert scalars(chunks, "cost/collision").values == replay["cost_collision"]
    env = _env()
    evaluation = run_episodes(env, actor, EPISODES * NUM_ENVS).episodes[::NUM_ENVS]
    env.close()
    for logged, expected in zip(report.episode_stats, evaluation, strict=True):
        assert logged.costs["lane"] == pytest.approx(expected.costs["lane"], rel=1e-12)
        assert logged.costs["collision"] == expected.costs["collision"]
        assert logged.distance == pytest.approx(expected.distance, rel=1e-12)


def test_a_collision_is_logged_as_its_termination(tmp_path):
    """The scripted follower from seed 1 on obstacle_loop runs into an obstacle at step 48."""
    env = crllk.make_env("obstacle_loop", observation="pixels", action="duty", seed=1,
                         overrides={"horizon": 60})
    report = record_episodes(env, FollowerPolicy(env), 1, tmp_path / "c.rrd")
    env.close()
    chunks = read_recording(tmp_path / "c.rrd")
    assert report.steps == 48
    assert scalars(chunks, "cost/collision").values[-1] == 1.0
    assert "ends (collision) after 48 steps" in series(chunks["events"],
                                                       "TextLog:text").values[-1][0]
    assert {"action/duty_left", "action/duty_right"} <= set(chunks)


@pytest.mark.parametrize("bad", ["below_a_file", "a_directory"])
def test_unwritable_path_raises_before_any_step(tmp_path, bad):
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    path = blocker / "x.rrd" if bad == "below_a_file" else tmp_path
    env = _env(1)

    def never(td):
        raise AssertionError("the env must not be stepped")

    with pytest.raises(RecordingError, match="cannot write the recording") as caught:
        record_episodes(env, never, 1, path)
    assert caught.value.path == str(path) and isinstance(caught.value, ValueError)
    env.close()


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def test_unreachable_viewer_is_reported_once_and_the_files_are_written(tmp_path, monkeypatch):
    """No ``rerun`` on PATH and no display: the viewer cannot run, the files are written; the
    failure is reported by the first recording of the process only, and not tried again."""
    monkeypatch.setenv("PATH", "")
    for name in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setattr(sinks, "VIEWER_PORT", _free_port())
    monkeypatch.setattr(sinks, "_FAILED_VIEWERS", set())
    attempts = []
    spawn_viewer = sinks.spawn_viewer

    def spawn(port):
        attempts.append(port)
        return spawn_viewer(port)

    monkeypatch.setattr(sinks, "spawn_viewer", spawn)
    env = _env(1)
    reports = [record_episodes(env, _actor(env), 1, tmp_path / f"v{k}.rrd", viewer="spawn")
               for k in range(2)]
    env.close()
    assert [len(r.warnings) for r in reports] == [1, 0] and len(attempts) == 1
    assert "rerun viewer (spawn) unavailable" in reports[0].warnings[0]
    for k, report in enumerate(reports):
        assert report.steps == HORIZON
        assert len(positions(read_recording(tmp_path / f"v{k}.rrd")).values) == HORIZON


def _listening_addresses(port: int) -> set[str]:
    """Local addresses of the TCP sockets listening on ``port`` (from /proc/net/tcp*)."""
    found = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        for line in Path(table).read_text().splitlines()[1:]:
            local, state = line.split()[1], line.split()[3]
            address, hex_port = local.rsplit(":", 1)
            if state == "0A" and int(hex_port, 16) == port:  # 0A: LISTEN
                found.add(socket.inet_ntop(socket.AF_INET, bytes.fromhex(address)[::-1])
                          if len(address) == 8 else address)
    return found


@pytest.mark.skipif(not Path("/proc/net/tcp").exists(), reason="needs Linux /proc/net/tcp")
def test_served_recording_listens_on_localhost_only(tmp_path, monkeypatch):
    port = _free_port()
    monkeypatch.setattr(sinks, "VIEWER_PORT", port)
    env = _env(1)
    actor = _actor(env)
    seen: list[set[str]] = []

    def policy(td):
        if not seen:
            seen.append(_listening_addresses(port))
        return actor(td)

    report = record_episodes(env, policy, 1, tmp_path / "s.rrd", viewer="serve")
    env.close()
    assert seen == [{"127.0.0.1"}]
    assert report.viewer_url == f"rerun+http://127.0.0.1:{port}/proxy"
    assert report.warnings == ()


def test_every_rerun_command_in_the_documentation_binds_to_localhost():
    """Without ``--bind`` the viewer, even one that only connects, listens on 0.0.0.0: every
    command of the README and of every page of the site binds to 127.0.0.1."""
    from docs_pages import page, pages

    text = "\n".join(page(name) for name in ["README.md", *pages()])
    commands = re.findall(r"^rerun .*$", text, flags=re.MULTILINE)  # code blocks
    commands += re.findall(r"`(rerun [^`]*)`", " ".join(text.split()))  # inline, unwrapped
    assert commands
    assert all("--bind 127.0.0.1" in command for command in commands), commands


def test_markings_lie_on_the_road():
    dmap = crllk.maps.load_map("obstacle_loop")
    for strips in (markings.white_marking_strips(dmap), markings.yellow_marking_strips(dmap),
                   markings.lane_centre_strips(dmap)):
        points = np.concatenate(strips)
        assert all(dmap.is_road(x, y) for x, y, _ in points)


def test_picture_of_a_recording(recorded, tmp_path):
    report, _, _ = recorded
    out = draw_recording(report.path, tmp_path / "picture.png")
    assert out.stat().st_size > 10_000
