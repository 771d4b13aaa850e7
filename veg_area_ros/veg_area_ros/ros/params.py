"""Parameters: declared with descriptors (ranges, allowed values), and the one rule for a start parameter
naming a file that cannot be read (`targets_file`, `calibration_file`, `camera_info_url`): the node logs an
error saying what it does without the file and keeps running; a value outside its range or choices at start
is refused by the node's start (rclpy refuses ranges at declaration, the nodes' own checks the same way).
Run-time changes are validated in an on-set callback (which changes nothing) and applied in a post-set
callback."""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.node import Node

Loaded = TypeVar("Loaded")
Value = TypeVar("Value")  # a parameter's type: its default's


def declare(node: Node, name: str, default: Value, description: str, *, low: float | None = None,
            high: float | None = None, choices: tuple[str, ...] = (), read_only: bool = False) -> Value:
    """Declare a parameter with a descriptor (and a range or the allowed values in its description)."""
    text = description + (f" One of: {', '.join(choices)}." if choices else "")
    descriptor = ParameterDescriptor(description=text, read_only=read_only)
    if low is not None and high is not None and not isinstance(default, bool):
        if isinstance(default, int):
            descriptor.integer_range = [IntegerRange(from_value=int(low), to_value=int(high), step=0)]
        elif isinstance(default, float):
            descriptor.floating_point_range = [FloatingPointRange(from_value=float(low), to_value=float(high),
                                                                  step=0.0)]
    value = node.declare_parameter(name, default, descriptor).value
    if choices and value not in choices:  # as a range is checked by rcl: a choice no code path knows is refused
        raise ValueError(f"parameter {name}: {value!r} is not one of {', '.join(map(str, choices))}")
    return value


def read_start_file(node: Node, parameter: str, read: Callable[[], Loaded], without: str) -> Loaded | None:
    """`read()` the file a start parameter names; on an error (OSError or ValueError, which the file readers'
    errors are) log it with what the node does `without` it, and return None."""
    try:
        return read()
    except (OSError, ValueError) as exc:
        node.get_logger().error(f"parameter {parameter}: {exc}; {without}")
        return None
