"""The model of the observer and MPC nodes, from their two file parameters (a node module:
it declares ROS parameters; the loading itself is :func:`hasel_wheel_sim.model_file.controller_model`)."""
from __future__ import annotations

from hasel_wheel_common.nodes.ros_common import text_param
from hasel_wheel_sim.jit import HAVE_NUMBA
from hasel_wheel_sim.model import Extensions
from hasel_wheel_sim.model_file import controller_model, describe_model
from hasel_wheel_sim.params import WheelParams


def declare_controller_model(node) -> tuple[WheelParams, Extensions, str]:
    """Declare ``wheel_params_file`` and ``model_file`` on ``node`` and load the model they
    name: (wheel parameters, extensions, one line for the log naming where it came from)."""
    wheel_file = node.declare_parameter(
        "wheel_params_file", "",
        text_param("model parameter YAML (wheel: {name: {value, unit}}); '' = built-in "
                   "paper values")).value
    model_file = node.declare_parameter(
        "model_file", "",
        text_param("model file (wheel: + extensions:, hasel_wheel_sim.model_file), e.g. an "
                   "identified model, in place of wheel_params_file; '' = not used")).value
    params, ext = controller_model(wheel_file, model_file)
    if not HAVE_NUMBA:
        node.get_logger().warning(
            "numba is not installed: the model core runs interpreted, 20-100x slower, so the "
            "MPC misses its deadlines and the observer may fall behind 300 Hz; install it "
            "(apt install python3-numba, or pip install numba)")
    return params, ext, describe_model(wheel_file, model_file, ext) + (
        "" if HAVE_NUMBA else "; model core interpreted (no numba)")
