"""drag_node: Cd = 2F / (rho U² Af) for every Af frame, with force (geometry_msgs/WrenchStamped) and velocity
(geometry_msgs/TwistStamped, linear), each one signed axis such as "+x", averaged over ±tolerance around the
frame's stamp; Af comes from `projected_area` (veg_area_msgs/ProjectedArea, the area node's). Publishes
`drag_coefficient` (veg_area_msgs/DragCoefficient: Cd, its std, force, velocity, Af, density, the sample counts
and the Af frame's warnings; header = the Af frame's), `drag_coefficient/vector` (deprecated, for one release:
the Vector3Stamped that `drag_coefficient` was, x = Cd, y = its std, z = U m/s; only while subscribed) and
`drag_coefficient/info` (JSON: the same and `unmatched_frames`; NaN or infinite instrument samples are left
out and counted in `rejected_samples`)."""

from __future__ import annotations

import json
from typing import TYPE_CHECKING

from geometry_msgs.msg import TwistStamped, Vector3Stamped, WrenchStamped
from rclpy.node import Node
from std_msgs.msg import String

from veg_area_msgs.msg import DragCoefficient, ProjectedArea

from ..drag import AXES, WATER_DENSITY, Drag, DragAligner, check_axis, component
from .health import publish_safely
from .params import declare
from .qos import RESULT_QOS
from .run import run_nodes

if TYPE_CHECKING:
    from builtin_interfaces.msg import Time


def _seconds(stamp: Time) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


class DragNode(Node):
    def __init__(self, name: str = "drag_node", **kwargs):
        super().__init__(name, **kwargs)
        density = declare(self, "density", WATER_DENSITY, "Water density, kg/m³.", low=900.0, high=1100.0,
                          read_only=True)
        tolerance = declare(self, "tolerance_s", 0.05, "Half-width of the window around each frame's stamp, s.",
                            low=0.0001, high=10.0, read_only=True)
        self.force_axis = declare(self, "force_axis", "+x", "Force component along the flow.", choices=AXES,
                                  read_only=True)
        self.velocity_axis = declare(self, "velocity_axis", "+x", "Velocity component along the flow.",
                                     choices=AXES, read_only=True)
        force_std = declare(self, "force_std_n", 0.0, "Noise of one force sample, N.", low=0.0, high=1e6,
                            read_only=True)
        velocity_std = declare(self, "velocity_std_m_s", 0.0, "Noise of one velocity sample, m/s.", low=0.0, high=1e3,
                               read_only=True)
        check_axis(self.force_axis)
        check_axis(self.velocity_axis)
        self.aligner = DragAligner(tolerance, density, force_std, velocity_std)
        self.cd_pub = self.create_publisher(DragCoefficient, "drag_coefficient", RESULT_QOS)
        # deprecated: the Vector3Stamped that `drag_coefficient` was, for recordings and nodes made for it
        self.cd_vector_pub = self.create_publisher(Vector3Stamped, "drag_coefficient/vector", RESULT_QOS)
        self.info_pub = self.create_publisher(String, "drag_coefficient/info", RESULT_QOS)
        # Af time -> its exact stamp, frame_id and warnings (a Cd says what made its Af less trustworthy)
        self.headers: dict[float, tuple[int, int, str, list[str]]] = {}
        self.create_subscription(WrenchStamped, "force", self._on_force, RESULT_QOS)
        self.create_subscription(TwistStamped, "velocity", self._on_velocity, RESULT_QOS)
        self.create_subscription(ProjectedArea, "projected_area", self._on_area, RESULT_QOS)

    def _on_force(self, msg: WrenchStamped) -> None:
        self.aligner.add_force(_seconds(msg.header.stamp), component(msg.wrench.force, self.force_axis))
        self._publish_ready()

    def _on_velocity(self, msg: TwistStamped) -> None:
        self.aligner.add_velocity(_seconds(msg.header.stamp), component(msg.twist.linear, self.velocity_axis))
        self._publish_ready()

    def _on_area(self, msg: ProjectedArea) -> None:
        t = _seconds(msg.header.stamp)
        self.headers[t] = (msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id, list(msg.warnings))
        self.aligner.add_area(t, msg.area_m2, msg.area_std_m2)
        self._publish_ready()

    def _publish_ready(self) -> None:
        for drag in self.aligner.ready():
            # the Af message's own stamp, not seconds through a float (exact-time joins must match)
            sec = int(drag.time_s // 1)
            stamp_sec, stamp_nanosec, frame_id, warnings = self.headers.pop(
                drag.time_s, (sec, round((drag.time_s - sec) * 1e9) % 1_000_000_000, "", []))
            out = drag_message(drag, self.aligner.density, warnings)
            out.header.stamp.sec, out.header.stamp.nanosec, out.header.frame_id = stamp_sec, stamp_nanosec, frame_id
            publish_safely(self, self.cd_pub, out)
            if self.cd_vector_pub.get_subscription_count() > 0:
                vector = Vector3Stamped(header=out.header)
                vector.vector.x, vector.vector.y, vector.vector.z = drag.cd, drag.cd_std, drag.velocity_m_s
                publish_safely(self, self.cd_vector_pub, vector)
            info = {**drag.__dict__, "area_warnings": warnings, "unmatched_frames": self.aligner.unmatched,
                    "rejected_samples": self.aligner.rejected_samples}
            publish_safely(self, self.info_pub, String(data=json.dumps(info)))
        if len(self.headers) > 1000:  # frames that never matched
            self.headers = dict(list(self.headers.items())[-100:])


def drag_message(drag: Drag, density: float, area_warnings: list[str]) -> DragCoefficient:
    """One Cd with what it was computed from, every field named (the header is the caller's)."""
    msg = DragCoefficient()
    msg.drag_coefficient, msg.drag_coefficient_std = float(drag.cd), float(drag.cd_std)
    msg.force_n, msg.velocity_m_s = float(drag.force_n), float(drag.velocity_m_s)
    msg.area_m2, msg.area_std_m2, msg.density_kg_m3 = float(drag.area_m2), float(drag.area_std_m2), float(density)
    msg.force_samples, msg.velocity_samples = int(drag.force_samples), int(drag.velocity_samples)
    msg.area_warnings = [str(w) for w in area_warnings]
    return msg


def main(args: list[str] | None = None) -> int:
    return run_nodes([DragNode], args)


if __name__ == "__main__":
    import sys

    sys.exit(main(sys.argv))
