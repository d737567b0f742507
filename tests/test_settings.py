"""Settings: one default per value, checks beside the fields, one line per bad value."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import pytest
from omegaconf import OmegaConf

from crllk.config import CONF_DIR, ConstraintConfig, TrainConfig
from crllk.errors import ConfigError
from crllk.settings import parse, parse_dotlist, positive, setting, unit_interval


@dataclass
class Inner:
    rate: float = setting(0.5, check=unit_interval)


@dataclass
class Outer:
    name: str = setting()
    count: int = setting(3, check=positive)
    inner: Inner = field(default_factory=Inner)
    by_name: dict[str, Inner] = field(default_factory=dict)

    def problems(self):
        if self.name == self.name.upper():
            yield "name", "must not be all capitals"


def test_defaults_and_nested_values():
    parsed = parse(Outer, {"name": "a", "by_name": {"x": {}}}, "src")
    assert parsed == Outer(name="a", count=3, inner=Inner(0.5), by_name={"x": Inner(0.5)})


@pytest.mark.parametrize(("values", "message"), [
    ({}, "src: name: Structured config of type `Outer` has missing mandatory value: name"),
    ({"name": "a", "count": 0}, "src: count: must be > 0, got 0"),
    ({"name": "a", "inner": {"rate": 2.0}}, "src: inner.rate: must lie in [0, 1], got 2.0"),
    ({"name": "a", "by_name": {"x": {"rate": -1}}},
     "src: by_name.x.rate: must lie in [0, 1], got -1.0"),
    ({"name": "a", "inner": {"rate": float("nan")}}, "src: inner.rate: must be finite, got nan"),
    ({"name": "a", "count": "three"}, "src: count: Value 'three' of type 'str' could not be "
                                       "converted to Integer"),
    ({"name": "AB"}, "src: name: must not be all capitals"),
])
def test_each_bad_value_names_its_field(values, message):
    with pytest.raises(ConfigError) as caught:
        parse(Outer, values, "src")
    assert str(caught.value) == message


def test_command_line_arguments():
    assert parse_dotlist(Outer, ["name=b", "inner.rate=0.25"], "cmd").inner.rate == 0.25
    with pytest.raises(ConfigError, match="cmd: count: expected key=value"):
        parse_dotlist(Outer, ["name=b", "count"], "cmd")


def _schema_default(path: list[str]):
    node = TrainConfig()
    for part in path:
        if isinstance(node, dict):  # algo.constraints.<name>: a ConstraintConfig's defaults
            node = ConstraintConfig(threshold=dataclasses.MISSING)
            continue
        node = getattr(node, part)
    return node


def _leaves(node, path=()):
    if isinstance(node, dict):
        for key, value in node.items():
            yield from _leaves(value, (*path, key))
    else:
        yield list(path), node


@pytest.mark.parametrize("group_file", sorted(p.relative_to(CONF_DIR).as_posix()
                                              for p in CONF_DIR.glob("*/*.yaml")))
def test_group_files_set_only_what_differs_from_the_schema(group_file):
    """Every value lives once: a group file (``algo/ppo.yaml``, ``obs/pixels.yaml``...) never
    restates a default of :class:`TrainConfig`."""
    data = OmegaConf.to_container(OmegaConf.load(CONF_DIR / group_file))
    group = group_file.split("/")[0]
    prefix = [] if group in ("obs", "action") else [group]  # global packages
    data.pop("defaults", None)  # agent files only choose groups
    for path, value in _leaves(data):
        default = _schema_default([*prefix, *path])
        assert default != value, f"{group_file}: {'.'.join(path)} restates the default {value!r}"


def test_train_yaml_holds_no_values():
    """The trainer's defaults are the schema's; train.yaml only chooses the groups."""
    data = OmegaConf.to_container(OmegaConf.load(CONF_DIR / "train.yaml"))
    assert set(data) == {"defaults", "hydra"}
