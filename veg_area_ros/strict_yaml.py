"""The one YAML reader for files users give the package (targets, calibrations). No ROS here.

Plain PyYAML keeps the last of two equal keys without a word (a calibration with `camera_matrix` twice
measured Af 5.8 % off) and expands aliases without limit (416 bytes of nested aliases took 9 GB and two
minutes before a MemoryError). This loader refuses both, and files over MAX_BYTES, before any work.
"""

from __future__ import annotations

from pathlib import Path

import yaml

MAX_BYTES = 1_000_000  # a targets or calibration file is a few kB


class StrictYamlError(ValueError):
    """A YAML text refused before or while parsing; the message says why (and where)."""


class _StrictLoader(yaml.SafeLoader):
    def compose_node(self, parent, index):
        if self.check_event(yaml.events.AliasEvent):
            event = self.peek_event()
            raise StrictYamlError(f"aliases (*{event.anchor}) are not allowed, at line {event.start_mark.line + 1}")
        return super().compose_node(parent, index)

    def construct_mapping(self, node, deep=False):
        keys = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            if key in keys:
                raise StrictYamlError(f"duplicate key {key!r} at line {key_node.start_mark.line + 1}")
            keys.add(key)
        return super().construct_mapping(node, deep)


_StrictLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _StrictLoader.construct_mapping)


def load_text(text: str):
    """Parse YAML text: duplicate keys and aliases are StrictYamlError, malformed YAML yaml.YAMLError."""
    if len(text) > MAX_BYTES:
        raise StrictYamlError(f"{len(text)} bytes: larger than any such file ({MAX_BYTES} at most)")
    return yaml.load(text, Loader=_StrictLoader)


def read_text(path: Path) -> str:
    """A file's text, refused unread when it is larger than MAX_BYTES."""
    size = path.stat().st_size
    if size > MAX_BYTES:
        raise StrictYamlError(f"{size} bytes: larger than any such file ({MAX_BYTES} at most)")
    return path.read_text(encoding="utf-8")
