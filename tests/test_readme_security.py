"""The documentation's Security page quotes the limits the code enforces, and its pages on
the robot the watchdog's."""

from __future__ import annotations

import pytest
from docs_pages import page, prose

from crllk.deployment.ros_node import FRAME_TIMEOUT_S
from crllk.files import STALE_TEMP_AGE_S
from crllk.images import MAX_FRAME_BYTES, MAX_FRAME_PIXELS
from crllk.network import RAY_LOCAL_ONLY
from crllk.recording.live import LIVE_PORT
from crllk.recording.viewer import VIEWER_PORT
from crllk.settings import MAX_SEED
from crllk.yaml_files import MAX_ALIAS_NODES, MAX_YAML_BYTES

SECTION = " ".join(page("security.md").split())


def test_the_security_section_quotes_the_limits():
    assert MAX_FRAME_PIXELS == 2560 * 1920 and "at most 2560×1920 pixels" in SECTION
    assert f"and {MAX_FRAME_BYTES // 2**20} MiB, checked from the header" in SECTION
    assert f"no frame has come for {FRAME_TIMEOUT_S:g} s (`--frame-timeout`)" in SECTION
    assert f"(or after {STALE_TEMP_AGE_S / 3600:g} h untouched)" in SECTION
    assert f"size-limited ({MAX_YAML_BYTES // 1024} KiB)" in SECTION
    assert f"may add at most {MAX_ALIAS_NODES:,} nodes" in SECTION
    assert f"(port {VIEWER_PORT})" in SECTION and f"port {LIVE_PORT}, `live_port`" in SECTION
    (variable, value), = RAY_LOCAL_ONLY.items()
    assert f"sets `{variable}={value}`" in SECTION
    assert MAX_SEED == 2**32 - 1 and "Seeds (at most 2³² − 1)" in SECTION


@pytest.mark.parametrize("where", ["sim-to-real.md", "tutorials/deploy.md"])
def test_the_deployment_pages_quote_the_watchdog(where):
    text = prose(where)
    assert f"whenever no frame has come for {FRAME_TIMEOUT_S:g} s (`--frame-timeout`)" in text
