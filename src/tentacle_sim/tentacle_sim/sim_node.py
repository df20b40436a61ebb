"""
sim_node: the simulated rig. Devices the drivers cannot tell from real ones, physics, camera.

Starts emulated supplies and stages on pseudo-terminals linked into ``device_dir`` (coil_x,
coil_y, coil_z, inserter, and backbone for a scene with one: tentacle_sim.sim_devices);
coils_node and inserter_node open them through config/sim/*.yaml. At ``camera_rate`` it
reads what the devices hold (the coils' currents, slew and R-L lag included; the stages'
true positions), solves the body (tentacle_sim.world: the scene's model and mismatch) and
publishes, all under the stamp of that moment:

- /camera/image_raw (mono8) and /camera/camera_info: the body in the phantom
  (tentacle_sim.camera), for tracker_node with the same ``base_px`` and ``metres_per_px``
- /sim/shape (nav_msgs/Path, frame coils): the true centreline, base to tip
- /sim/contact (sensor_msgs/JointState: ``count``, ``depth``): links through a wall or
  obstacle, the deepest crossing, m
- /sim/markers (visualization_msgs/MarkerArray) at ``markers_rate``: the body, the field, the
  desired path, obstacles and walls, frame coils (RViz, Foxglove)
- /diagnostics: the world (rate, physics and render time, inserted length, field, contact,
  mismatch) and the devices

Faults are injected from outside on ``device_dir/control`` (a Unix socket: one JSON request
a line, as the emulators take on stdin; ``sim_devices.ask`` sends one). On exit the devices
stop and their links go: stop the drivers first.
"""

import sys
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Point, PoseStamped
from nav_msgs.msg import Path
import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import ColorRGBA
from tentacle_common import contract
from tentacle_common.driver_node import (declare_parameters, diagnostic_status, publisher,
                                         run_node)
from tentacle_common.errors import ConfigError
from tentacle_planner.errors import PlanInputError
from tentacle_planner.scene import load_scene
from tentacle_planner.schedule_file import read_schedule
from tentacle_sim.camera import SimCamera
from tentacle_sim.params import NODE_NAME, SIM_PARAMS
from tentacle_sim.rate import RateMeter
from tentacle_sim.sim_devices import CONTROL, ControlSocket, DeviceDirBusy, SimDevices
from tentacle_sim.world import made_to_plan, World
from visualization_msgs.msg import Marker, MarkerArray

FIELD_ARROW_M_PER_T = 1.0  # the field arrow: 1 mm per mT


def _point(p):
    return Point(x=float(p[0]), y=float(p[1]), z=float(p[2]))


def _colour(r, g, b, a=1.0):
    return ColorRGBA(r=r, g=g, b=b, a=a)


class SimNode(Node):
    """The simulated rig's ROS side: parameters in, devices up, frames and truth out."""

    def __init__(self):
        """Load the scene, start the devices and the control socket, start the frame loop."""
        super().__init__(NODE_NAME)
        p = declare_parameters(self, SIM_PARAMS)
        if not p['scene']:
            raise ConfigError('scene: give the scene file (-p scene:=config/scenes/NAME.yaml)')
        try:
            self.scene = load_scene(p['scene'])
        except PlanInputError as exc:
            raise ConfigError(f'scene: {exc}') from None
        if p['schedule']:   # the tentacle as made to this plan
            try:
                self.scene = made_to_plan(self.scene, read_schedule(p['schedule']))
            except PlanInputError as exc:
                raise ConfigError(f'schedule: {exc}') from None
        if len(p['actuation_matrix']) != 9:
            raise ConfigError('actuation_matrix: give 9 numbers (3 x 3, row-major), T/A')
        self.period_s = 1.0 / p['camera_rate']
        self.world = World(self.scene, p['actuation_matrix'],
                           insertion_offset_m=p['insertion_offset_m'],
                           time_budget_s=p['physics_budget'] * self.period_s)
        self.camera = SimCamera(self.scene, p['metres_per_px'], p['base_px'], p['image_size'],
                                p['noise'], p['artefacts'])
        self.width_m = self.world.body_width_m()
        try:
            self.devices = SimDevices(
                p['device_dir'], p['coil_dialect'], self.world.has_backbone,
                resistance_ohm=p['coil_resistance_ohm'], inductance_h=p['coil_inductance_h'],
                compliance_v=p['compliance_v'])
        except (DeviceDirBusy, ValueError, OSError) as exc:
            raise ConfigError(f'devices not started: {exc}') from None
        self.control = ControlSocket(self.devices.dir / CONTROL, self.devices.control)
        self.image_pub = publisher(self, contract.IMAGE)
        self.info_pub = publisher(self, contract.CAMERA_INFO)
        self.shape_pub = publisher(self, contract.SIM_SHAPE)
        self.contact_pub = publisher(self, contract.SIM_CONTACT)
        self.markers_pub = publisher(self, contract.SIM_MARKERS)
        self.diag_pub = publisher(self, contract.DIAGNOSTICS)
        width, height = self.camera.size
        self.image = Image(height=height, width=width, encoding='mono8', step=width,
                           data=bytes(width * height))
        self.image.header.frame_id = contract.CAMERA_FRAME
        # Frames are written into the message in place (NOTES.md section 4: the setter copies).
        self.pixels = np.frombuffer(self.image.data, np.uint8).reshape(height, width)
        self.body, self.rate = None, RateMeter()
        self.problem = ''
        if p['markers_rate'] > 0:
            self.create_timer(1.0 / p['markers_rate'], self.publish_markers)
        self.create_timer(1.0, self.publish_diagnostics)
        self.get_logger().info(
            f"{self.scene.name}: devices in {self.devices.dir} ({p['coil_dialect']} supplies, "
            f"{', '.join(self.devices.devices)}), {p['camera_rate']:g} Hz, mismatch: "
            f'{self.scene.mismatch.describe()}')
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name='sim-frames', daemon=True)
        self._thread.start()

    # -- the frame loop ---------------------------------------------------------------------
    def _run(self):
        next_at = time.monotonic()
        while not self._stop.is_set():
            try:
                self.tick()
            except Exception as exc:  # a frame lost, not the simulator: say why, go on
                self.problem = f'{type(exc).__name__}: {exc}'
                self.get_logger().error(f'frame lost: {self.problem}', throttle_duration_sec=5.0)
            next_at += self.period_s
            self._stop.wait(max(next_at - time.monotonic(), 0.0))
            next_at = max(next_at, time.monotonic() - self.period_s)  # behind: do not catch up

    def tick(self):
        """Sample the devices, solve, publish the truth, then render and publish the frame."""
        stamp = self.get_clock().now().to_msg()
        currents = self.devices.currents_a()
        inserter = self.devices.travel_m('inserter')
        backbone = self.devices.travel_m('backbone') if self.world.has_backbone else 0.0
        body = self.world.step(currents, inserter, backbone)
        # The truth first: it does not wait for the frame's drawing and serialising.
        shape = Path()
        shape.header.stamp, shape.header.frame_id = stamp, contract.COILS_FRAME
        shape.poses = [PoseStamped(header=shape.header) for _ in body.points_m]
        for pose, point in zip(shape.poses, body.points_m):
            pose.pose.position = _point(point)
        self.shape_pub.publish(shape)
        contact = JointState(name=['count', 'depth'],
                             position=[float(body.contacts), body.contact_depth_m])
        contact.header.stamp, contact.header.frame_id = stamp, contract.COILS_FRAME
        self.contact_pub.publish(contact)
        self.body = body
        t0 = time.perf_counter()
        frame, _ = self.camera.frame(body.points_m, self.width_m,
                                     self.world.magnet_ranges_m(body.inserted_m))
        render_s = time.perf_counter() - t0
        self.image.header.stamp = stamp
        self.pixels[...] = frame
        self.image_pub.publish(self.image)
        self.info_pub.publish(CameraInfo(header=self.image.header, height=self.image.height,
                                         width=self.image.width))
        self.rate.tick(body.solve_s, render_s)

    # -- markers and diagnostics ------------------------------------------------------------
    def _marker(self, ns, kind, points=(), scale=(1e-3, 1e-3, 1e-3), colour=(1, 1, 1, 1),
                marker_id=0, position=None):
        marker = Marker(ns=ns, id=marker_id, type=kind, action=Marker.ADD)
        marker.header.frame_id = contract.COILS_FRAME
        marker.header.stamp = self.get_clock().now().to_msg()
        marker.pose.orientation.w = 1.0
        if position is not None:
            marker.pose.position = _point(position)
        marker.points = [_point(p) for p in points]
        marker.scale.x, marker.scale.y, marker.scale.z = (float(v) for v in scale)
        marker.color = _colour(*colour)
        return marker

    def publish_markers(self):
        """Publish the body, the field at the insertion point, the path, the phantom."""
        body, scene = self.body, self.scene
        markers = [self._marker('path', Marker.LINE_STRIP, scene.path.points_m,
                                (2e-4, 0, 0), (0.2, 0.8, 0.2, 0.8))]
        for i, sphere in enumerate(scene.obstacles):
            d = 2 * sphere.radius_m
            markers.append(self._marker('obstacles', Marker.SPHERE, (), (d, d, d),
                                        (0.6, 0.6, 0.6, 0.6), i, sphere.centre_m))
        for i, wall in enumerate(scene.walls):
            markers.append(self._marker('walls', Marker.LINE_STRIP, wall.points_m,
                                        (3e-4, 0, 0), (0.6, 0.6, 0.6, 0.9), i))
        if body is not None and len(body.points_m) >= 2:
            markers.append(self._marker('body', Marker.LINE_STRIP, body.points_m,
                                        (self.width_m, 0, 0), (0.9, 0.4, 0.2, 1.0)))
            base = body.points_m[0]
            markers.append(self._marker(
                'field', Marker.ARROW, (base, base + FIELD_ARROW_M_PER_T * body.field_t),
                (3e-4, 8e-4, 1e-3), (0.2, 0.4, 1.0, 1.0)))
        self.markers_pub.publish(MarkerArray(markers=markers))

    def publish_diagnostics(self):
        """Publish the world's status and the devices'."""
        body, figures = self.body, self.rate.figures()
        if body is None:
            level, message = ('error', self.problem) if self.problem else ('warn', 'starting')
            values = {}
        else:
            level, message = 'ok', f'{figures["rate_hz"]:.1f} Hz'
            if body.contacts:
                level, message = 'warn', (f'{body.contacts} link(s) through the phantom, '
                                          f'{body.contact_depth_m * 1e3:.2f} mm deep')
            if self.problem:
                level, message = 'warn', f'{message}; last lost frame: {self.problem}'
            values = {'inserted_m': body.inserted_m, 'backbone_m': body.backbone_m,
                      'field_t': [round(float(v), 7) for v in body.field_t],
                      'converged': body.converged, 'solver': body.reason,
                      'contacts': body.contacts, 'contact_depth_m': body.contact_depth_m,
                      **figures}
        values['mismatch'] = self.scene.mismatch.describe()
        statuses = [diagnostic_status(f'{NODE_NAME}: world', self.scene.name, level, message,
                                      values)]
        for name, device in self.devices.devices.items():
            statuses.append(diagnostic_status(
                f'{NODE_NAME}: device {name}', device.port, 'ok' if device.connected
                else 'warn', 'linked' if device.connected else 'disconnected (fault injected)',
                {'received': len(device.log), 'pending_faults': device.pending_faults()}))
        msg = DiagnosticArray(status=statuses)
        msg.header.stamp = self.get_clock().now().to_msg()
        self.diag_pub.publish(msg)

    def shutdown(self):
        """Stop the frame loop, the control socket and the devices (their links go)."""
        self._stop.set()
        self._thread.join(timeout=5.0)
        self.control.close()
        self.devices.stop()
        return f'devices stopped, links removed from {self.devices.dir}'


def main(args=None):
    """Run the simulated rig until a signal; then stop its devices."""
    run_node(sys.argv[1:] if args is None else list(args), NODE_NAME, SIM_PARAMS, __doc__,
             SimNode, lambda node: node.shutdown())


if __name__ == '__main__':
    main()
