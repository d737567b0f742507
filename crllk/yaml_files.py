"""Reading task and map files (YAML) safely: size-limited, duplicate keys and alias bombs
refused, every problem one :class:`~crllk.errors.MapError` naming the file and the line."""

from __future__ import annotations

from pathlib import Path

import yaml

from crllk.errors import MapError

MAX_YAML_BYTES = 512 * 1024
"""Largest task or map file read (bytes), checked before parsing: 14 times the largest Duckietown
map file, and about 4 s of parsing."""
MAX_ALIAS_NODES = 10_000
"""Nodes that the aliases of a YAML document may add when expanded (an anchored list of 100
entries used 100 times). A few hundred bytes of nested anchors and aliases otherwise expand to
millions of nodes ("billion laughs"), which an error message about the value would print."""

class _UniqueKeyLoader(yaml.SafeLoader):
    """PyYAML's safe loader, refusing a key that appears twice in one mapping and a document
    whose aliases expand too far (:data:`MAX_ALIAS_NODES`)."""

    def construct_document(self, node: yaml.Node) -> object:
        added = _expanded_nodes(node) - _distinct_nodes(node)
        if added > MAX_ALIAS_NODES:
            raise _AliasExpansionError(f"its aliases expand to {added} more nodes, over the "
                                       f"{MAX_ALIAS_NODES} a task, map or run configuration "
                                       "file may add")
        return super().construct_document(node)

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict:
        seen: set = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    None, None, f"duplicate key {key!r}", key_node.start_mark)
            if isinstance(key, str | int | float | bool | None):
                seen.add(key)
        return super().construct_mapping(node, deep)


class _AliasExpansionError(yaml.YAMLError):
    """A document whose aliases expand past :data:`MAX_ALIAS_NODES`, or into themselves."""


def _children(node: yaml.Node) -> list[yaml.Node]:
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    if isinstance(node, yaml.MappingNode):
        return [part for pair in node.value for part in pair]
    return []


def _distinct_nodes(root: yaml.Node) -> int:
    seen: set[int] = set()
    stack = [root]
    while stack:
        node = stack.pop()
        if id(node) not in seen:
            seen.add(id(node))
            stack.extend(_children(node))
    return len(seen)


def _expanded_nodes(root: yaml.Node) -> int:
    """Nodes of the document with every alias replaced by a copy of its node."""
    sizes: dict[int, int] = {}
    open_nodes: set[int] = set()

    def size(node: yaml.Node) -> int:
        key = id(node)
        if key in sizes:
            return sizes[key]
        if key in open_nodes:
            raise _AliasExpansionError("an alias refers to a node that contains it")
        open_nodes.add(key)
        sizes[key] = 1 + sum(size(child) for child in _children(node))
        open_nodes.discard(key)
        return sizes[key]

    return size(root)


def read_yaml(path: Path) -> object:
    """Reads a YAML file, turning syntax errors into a :class:`MapError` naming the file.

    Raises:
        MapError: also for a file larger than :data:`MAX_YAML_BYTES` or whose aliases expand
            past :data:`MAX_ALIAS_NODES`.
    """
    try:
        size = path.stat().st_size
        if size > MAX_YAML_BYTES:
            raise MapError(path, "<file>", f"{size} bytes, more than the {MAX_YAML_BYTES} a task, "
                           "map or run configuration file may have")
        return yaml.load(path.read_text(encoding="utf-8"), Loader=_UniqueKeyLoader)
    except UnicodeDecodeError as err:
        raise MapError(path, "<file>", f"not a text file (UTF-8): byte {err.start} cannot be "
                       "decoded") from None
    except OSError as err:
        raise MapError(path, "<file>", f"cannot read: {err.strerror}") from None
    except _AliasExpansionError as err:
        raise MapError(path, "<file>", str(err)) from None
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f"line {mark.line + 1}" if mark else "<file>"
        raise MapError(path, where, f"not valid YAML: {getattr(err, 'problem', err)}") from None
