"""drag_node: Cd = 2F / (rho U² Af) for every Af frame, with force (geometry_msgs/WrenchStamped) and velocity
(geometry_msgs/TwistStamped, linear), each one signed axis such as "+x", averaged over ±tolerance around the
frame's stamp; Af comes from `projected_area` (veg_area_msgs/ProjectedArea, the area node's). Publishes
`drag_coefficient` (Vector3Stamped: x = Cd, y = its standard deviation, z = U m/s; header = the Af frame's) and
`drag_coefficient/info` (JSON with force, velocity, Af, the Af frame's warnings and the sample counts; NaN or
infinite instrument samples are left out and counted in `rejected_samples`)."""

from __future__ import annotations

import json

from geometry_msgs.msg import TwistStamped, Vector3Stamped, WrenchStamped
from rclpy.node import Node
from std_msgs.msg import String

from veg_area_msgs.msg import ProjectedArea

from ..drag import AXES, WATER_DENSITY, DragAligner, check_axis, component
from .health import publish_safely
from .params import declare
from .qos import RESULT_QOS
from .run import run_nodes


def _seconds(stamp) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


class DragNode(Node):
    def __init__(self, name: str = "drag_node", **kwargs):
        super().__init__(name, **kwargs)
        density = declare(self, "density", WATER_DENSITY, "Water density, kg/m³.", low=900.0, high=1100.0)
        tolerance = declare(self, "tolerance_s", 0.05, "Half-width of the window around each frame's stamp, s.",
                            low=0.0001, high=10.0)
        self.force_axis = declare(self, "force_axis", "+x", "Force component along the flow.", choices=AXES,
                                  read_only=True)
        self.velocity_axis = declare(self, "velocity_axis", "+x", "Velocity component along the flow.",
                                     choices=AXES, read_only=True)
        force_std = declare(self, "force_std_n", 0.0, "Noise of one force sample, N.", low=0.0, high=1e6)
        velocity_std = declare(self, "velocity_std_m_s", 0.0, "Noise of one velocity sample, m/s.", low=0.0, high=1e3)
        check_axis(self.force_axis)
        check_axis(self.velocity_axis)
        self.aligner = DragAligner(tolerance, density, force_std, velocity_std)
        self.cd_pub = self.create_publisher(Vector3Stamped, "drag_coefficient", RESULT_QOS)
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
            out = Vector3Stamped()
            # the Af message's own stamp, not seconds through a float (exact-time joins must match)
            sec = int(drag.time_s // 1)
            out.header.stamp.sec, out.header.stamp.nanosec, out.header.frame_id, warnings = self.headers.pop(
                drag.time_s, (sec, round((drag.time_s - sec) * 1e9) % 1_000_000_000, "", []))
            out.vector.x, out.vector.y, out.vector.z = drag.cd, drag.cd_std, drag.velocity_m_s
            publish_safely(self, self.cd_pub, out)
            info = {**drag.__dict__, "area_warnings": warnings, "unmatched_frames": self.aligner.unmatched,
                    "rejected_samples": self.aligner.rejected_samples}
            publish_safely(self, self.info_pub, String(data=json.dumps(info)))
        if len(self.headers) > 1000:  # frames that never matched
            self.headers = dict(list(self.headers.items())[-100:])


def main(args: list[str] | None = None) -> int:
    return run_nodes([DragNode], args)


if __name__ == "__main__":
    import sys

    sys.exit(main(sys.argv))
