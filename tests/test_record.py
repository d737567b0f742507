"""Rerun recordings: written from real rollouts, read back with ``rerun.chunk.RrdReader`` and
checked against an unrecorded replay; failures of the file and of the viewer."""

from __future__ import annotations

import socket
from pathlib import Path

import numpy as np
import pytest
import torch
from rerun.chunk import RrdReader
from torchrl.envs.utils import step_mdp

import crllk
from crllk import record
from crllk.evaluation import run_episodes
from crllk.lane_keeping import state_feature_names
from crllk.models import ModelConfig, make_actor
from crllk.record import (
    ACTION_ENTITY_PATHS,
    ENTITY_PATHS,
    FollowerPolicy,
    RecordingError,
    read_recording,
    record_episodes,
)
from crllk.recording_picture import draw_recording, positions, scalars, series

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
    with torch.no_grad(), record.set_exploration_type(record.ExplorationType.DETERMINISTIC):
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
    expected = {*ENTITY_PATHS, *ACTION_ENTITY_PATHS["discrete"], "lagrange/lane",
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


def test_recording_logs_episode_boundaries_and_statistics(recorded):
    report, chunks, _ = recorded
    texts = [t[0] for t in series(chunks["events"], "TextLog:text").values]
    assert [t.split(" ", 3)[2] for t in texts] == ["starts", "ends", "starts", "ends"]
    assert "ends (time limit) after 30 steps" in texts[1]
    lengths = scalars(chunks, "episode/length")
    assert lengths.values == [HORIZON] * EPISODES
    assert scalars(chunks, "episode/lane_cost").values == pytest.approx(
        [s.lane_cost for s in report.episode_stats])


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
        assert logged.lane_cost == pytest.approx(expected.lane_cost, rel=1e-12)
        assert logged.collisions == expected.collisions
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


def test_unreachable_viewer_warns_and_still_writes_the_file(tmp_path, monkeypatch):
    """No ``rerun`` on PATH and no display: the viewer cannot run, the file is written."""
    monkeypatch.setenv("PATH", "")
    for name in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setattr(record, "VIEWER_PORT", _free_port())
    env = _env(1)
    with pytest.warns(RuntimeWarning, match=r"rerun viewer \(spawn\) unavailable"):
        report = record_episodes(env, _actor(env), 1, tmp_path / "v.rrd", viewer="spawn")
    env.close()
    assert len(report.warnings) == 1 and report.steps == HORIZON
    assert len(positions(read_recording(tmp_path / "v.rrd")).values) == HORIZON


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
    monkeypatch.setattr(record, "VIEWER_PORT", port)
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


def test_markings_lie_on_the_road():
    dmap = crllk.maps.load_map("obstacle_loop")
    for strips in (record.white_marking_strips(dmap), record.yellow_marking_strips(dmap),
                   record.lane_centre_strips(dmap)):
        points = np.concatenate(strips)
        assert all(dmap.is_road(x, y) for x, y, _ in points)


def test_picture_of_a_recording(recorded, tmp_path):
    report, _, _ = recorded
    out = draw_recording(report.path, tmp_path / "picture.png")
    assert out.stat().st_size > 10_000
