"""The one YAML reader for files users give the package (targets, calibrations), and the writer whose YAML
other tools read whole (`dump_portable`). No ROS here.

Plain PyYAML keeps the last of two equal keys without a word (a calibration with `camera_matrix` twice
measured Af 5.8 % off) and expands aliases without limit (416 bytes of nested aliases took 9 GB and two
minutes before a MemoryError). This loader refuses both, and files over MAX_BYTES, before any work.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import yaml

from .files import special_file

MAX_BYTES = 1_000_000  # a targets or calibration file is a few kB


class StrictYamlError(ValueError):
    """A YAML text refused before or while parsing; the message says why (and where)."""


class _StrictLoader(yaml.SafeLoader):
    def compose_node(self, parent: yaml.Node | None, index: object) -> yaml.Node | None:
        if self.check_event(yaml.events.AliasEvent):
            event = self.peek_event()
            raise StrictYamlError(f"aliases (*{event.anchor}) are not allowed, at line {event.start_mark.line + 1}")
        return super().compose_node(parent, index)

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict:
        keys = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            if key in keys:
                raise StrictYamlError(f"duplicate key {key!r} at line {key_node.start_mark.line + 1}")
            keys.add(key)
        return super().construct_mapping(node, deep)


_StrictLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _StrictLoader.construct_mapping)


def load_text(text: str) -> Any:
    """Parse YAML text: duplicate keys and aliases are StrictYamlError, malformed YAML yaml.YAMLError."""
    if len(text) > MAX_BYTES:
        raise StrictYamlError(f"{len(text)} bytes: larger than any such file ({MAX_BYTES} at most)")
    return yaml.load(text, Loader=_StrictLoader)


def read_bytes(path: Path) -> bytes:
    """A file's bytes, refused unread when it is larger than MAX_BYTES or no regular file (a device, a pipe)."""
    problem = special_file(path)
    if problem:
        raise StrictYamlError(problem)
    size = path.stat().st_size
    if size > MAX_BYTES:
        raise StrictYamlError(f"{size} bytes: larger than any such file ({MAX_BYTES} at most)")
    return path.read_bytes()


# what a file given where a text file belongs most often is instead: an image (the frame and the calibration
# swapped on a command line)
_BINARY_KINDS = ((b"\x89PNG\r\n\x1a\n", "a PNG image"), (b"\xff\xd8\xff", "a JPEG image"),
                 (b"II*\x00", "a TIFF image"), (b"MM\x00*", "a TIFF image"), (b"%PDF", "a PDF document"),
                 (b"PK\x03\x04", "a zip archive"))


def decode_text(data: bytes) -> str:
    """A file's bytes as UTF-8 text, its line ends as Python's text files give them (UnicodeDecodeError if not;
    StrictYamlError naming what it is for an image, a PDF or a zip archive)."""
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        kind = next((name for magic, name in _BINARY_KINDS if data.startswith(magic)), None)
        if kind:
            raise StrictYamlError(f"is {kind}, not a text file") from None
        raise
    return text.replace("\r\n", "\n").replace("\r", "\n")


def read_text(path: Path) -> str:
    """A file's text (`read_bytes`, `decode_text`)."""
    return decode_text(read_bytes(path))


class _PortableDumper(yaml.SafeDumper):
    """YAML that OpenCV's FileStorage and yaml-cpp (ROS's camera_calibration_parsers) read whole: every string
    that is not a plain word double-quoted (an unquoted `board: chessboard:9x6:0.04` stopped FileStorage with
    "Incorrect indentation"), and every list in flow style (FileStorage refuses a block list at its key's
    indentation)."""


_PLAIN_WORD = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
_RESERVED_WORDS = {"null", "true", "false", "yes", "no", "on", "off", "y", "n", "none"}


def _represent_str(dumper: yaml.SafeDumper, text: str) -> yaml.Node:
    plain = _PLAIN_WORD.match(text) is not None and text.lower() not in _RESERVED_WORDS
    return dumper.represent_scalar("tag:yaml.org,2002:str", text, style=None if plain else '"')


def _represent_list(dumper: yaml.SafeDumper, items: list) -> yaml.Node:
    return dumper.represent_sequence("tag:yaml.org,2002:seq", items, flow_style=True)


_PortableDumper.add_representer(str, _represent_str)
_PortableDumper.add_representer(list, _represent_list)
_PortableDumper.add_representer(tuple, _represent_list)


def dump_portable(content: object) -> str:
    """YAML text of plain data (dicts, lists, strings, numbers) that PyYAML, OpenCV's FileStorage and yaml-cpp
    all read as it was written; keys in their order; no line folded (FileStorage cannot read a folded string)."""
    return yaml.dump(content, Dumper=_PortableDumper, sort_keys=False, default_flow_style=None, width=10**9,
                     allow_unicode=True)
