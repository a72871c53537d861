"""sim_node: the plant simulator as a drop-in replacement for the driver node.

Publishes the driver's topics with the driver's types (``telemetry``, ``joint_states``,
``/diagnostics``) plus the ground truth ``sim/true_state``, and takes ``command`` like the
driver does.  Runs in real time (``time_scale`` 1.0) or scaled time, from the moment its
controller is connected, a node that publishes ``command`` and subscribes to ``telemetry`` (or
after ``start_timeout``): until then the wheel is held at t = 0, so it does not coast to a stop before its controller is heard.

The plant is ``wheel_params_file`` with ``plant_file`` (seed, switching, effects).  With
``model_file`` set (e.g. an identified model), the model file's parameters and extensions are
the plant's dynamics instead: ``wheel_params_file`` is not read, and ``plant_file`` gives only
the seed, the switching and the sensor/link effects (encoder, glitches, dropouts, latency).  A
dynamic effect enabled in ``plant_file`` as well is refused at start (the dynamics would come
from two places), e.g. plant_realistic.yaml; config/plant.yaml has none.
"""
from __future__ import annotations

import dataclasses
import time
from pathlib import Path

from diagnostic_msgs.msg import DiagnosticStatus
from hasel_wheel_msgs.msg import ActuationCommand, HybridStateEstimate, WheelTelemetry
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool

from hasel_wheel_common import samples
from hasel_wheel_common import topics
from hasel_wheel_common.published_count import PublishedCount
from hasel_wheel_common.nodes.ros_common import (create_publishers, fill, float_param,
                                                 publish_status, qos_profile, run_node,
                                                 int_param, text_param)
from hasel_wheel_sim.plant import load_plant_model
from hasel_wheel_sim.sim_runtime import SimRuntime

_CONFIG = Path(__file__).resolve().parent / "config"


class SimNode(Node):

    def __init__(self) -> None:
        super().__init__("hasel_wheel_sim")
        wheel_file = self.declare_parameter(
            "wheel_params_file", str(_CONFIG / "wheel_params.yaml"),
            text_param("model parameter YAML (wheel: {name: {value, unit}})")).value
        plant_file = self.declare_parameter(
            "plant_file", str(_CONFIG / "plant.yaml"),
            text_param("plant YAML: seed, switching mode, effects")).value
        model_file = self.declare_parameter(
            "model_file", "",
            text_param("model file (wheel: + extensions:, hasel_wheel_sim.model_file) as the "
                       "plant's dynamics, in place of wheel_params_file and plant_file's dynamic "
                       "effects; '' = not used")).value
        w0 = self.declare_parameter(
            "initial_speed", 0.0, float_param("wheel speed at start [rad/s]; 0 = from rest",
                                              0.0, 20.0, True)).value
        scale = self.declare_parameter(
            "time_scale", 1.0, float_param("simulated seconds per wall second [1]", 0.01, 100.0)).value
        seed_offset = self.declare_parameter(
            "seed_offset", 0,
            int_param("added to plant_file's seed (wheel i of a multi-wheel launch: i) [1]",
                      0, 1_000_000, True)).value
        self.start_timeout = self.declare_parameter(
            "start_timeout", 5.0,
            float_param("hold the wheel at t = 0 until a node that publishes commands "
                        "subscribes to telemetry, or this long [s]; 0 = start at once", 0.0, 60.0,
                        True)).value
        self.telemetry_subscribers = self.declare_parameter(
            "telemetry_subscribers", 0,
            int_param("also hold the wheel until this many subscriptions match telemetry (the "
                      "launch files: the observer, the MPC and the recorder) [1]", 0, 100,
                      True)).value
        self.declare_parameter("frame_id", "wheel", text_param("frame_id of telemetry headers"))
        self.declare_parameter("diagnostics_period", 1.0,
                               float_param("period of /diagnostics [s]", 0.1, 60.0, True))
        self.frame_id = self.get_parameter("frame_id").value
        params, plant = load_plant_model(wheel_file, plant_file, model_file)
        plant = dataclasses.replace(plant, seed=plant.seed + seed_offset)
        self.core = SimRuntime(params, plant, w0, scale)
        self.add_on_set_parameters_callback(self._on_set_parameters)

        pubs = create_publishers(self, (topics.TELEMETRY, topics.JOINT_STATES, topics.TRUE_STATE,
                                        topics.DIAGNOSTICS))
        self.pub_tlm, self.pub_js, self.pub_truth, self.pub_diag = pubs.values()
        self.sub_cmd = self.create_subscription(ActuationCommand, topics.COMMAND.name,
                                                self._on_command, qos_profile(topics.COMMAND.qos))
        self.create_subscription(Bool, topics.HV_REQUEST.name, self._on_hv_request,
                                 qos_profile(topics.HV_REQUEST.qos))
        self.t0_ns = self.get_clock().now().nanoseconds
        self.started = False
        self.created = time.monotonic()
        self.published = 0                     # telemetry samples in this diagnostics window
        self.published_total = PublishedCount()
        self.window_t0 = self.created
        self.create_timer(0.01, self._on_tick)
        self.create_timer(self.get_parameter("diagnostics_period").value, self._on_diagnostics)
        self.get_logger().info(f"simulating {model_file or wheel_file} with {plant_file} (seed "
                               f"{plant.seed}) at x{scale:g}")

    def _on_set_parameters(self, params) -> SetParametersResult:
        for p in params:
            if p.name == "time_scale":
                try:
                    self.core.set_time_scale(p.value)
                except ValueError as exc:
                    return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _on_hv_request(self, msg: Bool) -> None:
        """``hv_request``: false switches HV off (every pad off, commands refused), true on
        again (:meth:`SimRuntime.set_hv`)."""
        if bool(msg.data) != self.core.hv_enabled:
            self.core.set_hv(bool(msg.data))
            log = self.get_logger().info if msg.data else self.get_logger().warn
            log(f"HV {'on' if msg.data else 'off'} on request (hv_request)")

    def _on_command(self, msg: ActuationCommand) -> None:
        reason = self.core.submit(samples.Command(int(msg.n_a), float(msg.phi_a),
                                                  float(msg.phi_d), int(msg.sequence),
                                                  now=bool(msg.now)))
        if reason:
            self.get_logger().warn(f"command {msg.sequence} rejected, HV stays off for it: {reason}")

    def _stamp_time(self, t: float) -> float:
        """Header time [s]: ROS time at start plus simulated time."""
        return self.t0_ns * 1e-9 + t

    def _start(self) -> bool:
        """True once the simulation runs.  It starts when the loop is connected (a node that
        publishes commands, matched to our subscription, also subscribes to our telemetry; a
        recorder's subscription alone does not count) or after start_timeout, so the run, and
        its recording, begin with the controller listening (a coasting wheel would otherwise
        lose speed while DDS discovery keeps the controller's first command from it).  The
        pacing and the header clock are anchored here, at t = 0."""
        def nodes(infos):
            return {(i.node_namespace, i.node_name) for i in infos}
        connected = self.sub_cmd.get_publisher_count() > 0 and bool(
            nodes(self.get_subscriptions_info_by_topic(self.pub_tlm.topic_name))
            & nodes(self.get_publishers_info_by_topic(self.sub_cmd.topic_name))) and \
            self.pub_tlm.get_subscription_count() >= self.telemetry_subscribers
        waited = time.monotonic() - self.created
        if not (connected or waited >= self.start_timeout):
            return False
        self.started = True
        self.t0_ns = self.get_clock().now().nanoseconds
        self.get_logger().info(
            "wheel started: its controller is connected" if connected else
            f"wheel started without a controller after {waited:.1f} s (start_timeout)")
        return True

    def _on_tick(self) -> None:
        if not (self.started or self._start()):
            return
        for out in self.core.run_until(time.monotonic()):
            t = self._stamp_time(out.t)
            if out.sample is not None:
                s = out.sample
                host = s._replace(t=self._stamp_time(s.t))
                self.pub_tlm.publish(fill(WheelTelemetry(), samples.telemetry_msg(host, self.frame_id)))
                self.published += 1
                self.published_total.count(s.sequence)
                self.pub_js.publish(fill(JointState(), samples.joint_state_msg(host)))
            x = out.truth
            self.pub_truth.publish(fill(HybridStateEstimate(), samples.state_msg(
                t, x.xi1, x.xi2, x.q, x.act_counter, x.deact_counter, x.eta)))

    def _on_diagnostics(self) -> None:
        now = time.monotonic()
        d = self.core.diagnostics()
        d["telemetry_rate_hz"] = f"{self.published / max(now - self.window_t0, 1e-9):.1f}"
        d.update(self.published_total.diagnostics())
        d["started"] = str(self.started)
        self.published, self.window_t0 = 0, now
        if not self.started:
            level, text = DiagnosticStatus.WARN[0], "waiting for the controller (wheel at t = 0)"
        elif self.core.commands_rejected or self.core.overruns:
            level, text = DiagnosticStatus.WARN[0], (
                f"simulating; {self.core.commands_rejected} commands rejected, "
                f"{self.core.overruns} overruns (the timer fell behind) so far")
        else:
            level, text = DiagnosticStatus.OK[0], "simulating"
        publish_status(self, self.pub_diag, "simulator", "hasel_wheel_sim", level, text, d)


def main(args=None):
    run_node(SimNode, "hasel_wheel_sim", args)


if __name__ == '__main__':
    main()
