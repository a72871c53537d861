"""Stopping the graph (docs/ros2.md, "Stopping the graph"): however a launch is stopped,
every process ends with status 0 and no line says ERROR, and the recording is closed.

Each case runs ``launch_stopper.py`` (a script, so that it can adopt what a dead launch
leaves behind) on the sim closed loop, or on a replay that ends by itself.  Needs ROS 2 in a
loopback-only network namespace (``hasel_wheel_common.ros_sandbox``); skips elsewhere.
"""
import json
import subprocess
import sys
from pathlib import Path

import pytest

from hasel_wheel_bag.layout import bag_metadata
from hasel_wheel_common.ros_sandbox import ros_graph_unavailable

REASON = ros_graph_unavailable()
pytestmark = pytest.mark.skipif(REASON is not None, reason=str(REASON))
STOPPER = Path(__file__).with_name("launch_stopper.py")
#: the graph's processes in the sim closed loop
SIM_LOOP = ["bag_record-1", "mpc_node-3", "observer_node-2", "sim_node-4"]


def _stop(way: str, workdir: Path, *launch_args: str) -> dict:
    out = subprocess.run([sys.executable, str(STOPPER), way, str(workdir), *launch_args],
                         capture_output=True, text=True, timeout=600, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _closed(bag: Path) -> bool:
    """The recorder wrote its metadata.yaml on the way out (a killed one does not)."""
    return (bag / "metadata.yaml").exists() and bag_metadata(bag) is not None


@pytest.mark.parametrize("way", ["ctrl-c", "sigint-group", "sigterm-node"])
def test_every_process_of_the_loop_ends_cleanly(way, tmp_path):
    r = _stop(way, tmp_path, "sim_closed_loop.launch.py", "namespace:=stop",
              f"bag_dir:={tmp_path / 'bag'}")
    assert r["started"], "the wheel never started"
    assert r["launch_status"] == 0
    assert r["processes"] == SIM_LOOP
    assert r["ended"] == {name: ["has finished cleanly", 0] for name in SIM_LOOP}
    assert r["error_lines"] == []
    assert _closed(tmp_path / "bag")


def test_the_bag_holds_every_reference_sent_and_every_telemetry_sample(tmp_path):
    """A reference by ``ros2 topic pub --once`` is recorded as sent (beside the MPC node's
    republication of it), one by ``ros2 param set`` as the MPC node republishes it, the
    initial one as announced to the recorder; and the bag holds every telemetry sample the
    simulator reported publishing."""
    from hasel_wheel_bag.reader import read_messages
    from hasel_wheel_bringup.bag_completeness import bag_completeness

    bag = tmp_path / "bag"
    r = _stop("ctrl-c", tmp_path, "--references", "/ref", "sim_closed_loop.launch.py",
              "namespace:=ref", f"bag_dir:={bag}")
    assert r["launch_status"] == 0 and r["error_lines"] == []
    sent = sorted(m.data for _, _, m in read_messages(bag, topics=["/ref/reference_speed"]))
    assert sent == [1.0, 1.5, 1.5, 2.0]
    (wheel,) = bag_completeness(bag)
    assert wheel.namespace == "/ref" and wheel.published > 0 and wheel.missing == 0


def test_sigterm_to_launch_leaves_nothing_running_and_the_bag_closed(tmp_path):
    """Jazzy's launch dies on SIGTERM without stopping its processes (status -15); every
    one of them then stops by itself with status 0."""
    r = _stop("sigterm-launch", tmp_path, "sim_closed_loop.launch.py", "namespace:=stop",
              f"bag_dir:={tmp_path / 'bag'}")
    assert r["started"] and r["launch_status"] == -15
    assert sorted(r["orphan_statuses"]) == [0] * len(SIM_LOOP)
    assert r["error_lines"] == []
    assert _closed(tmp_path / "bag")


def test_a_launch_that_ends_itself_ends_every_process_cleanly(tmp_path):
    """The replay launch shuts down when its bag has been played."""
    from hasel_wheel_mpc.closed_loop import run_closed_loop
    from hasel_wheel_mpc.recorder import Recorder

    rec = Recorder(tmp_path / "source")
    run_closed_loop(profile=((0.0, 1.0),), duration=5.0, recorder=rec)
    rec.close()
    r = _stop("launch-ends", tmp_path, "replay.launch.py", f"bag:={tmp_path / 'source'}",
              f"bag_dir:={tmp_path / 'replayed'}")
    names = ["bag_play-4", "bag_record-1", "mpc_node-3", "observer_node-2"]
    assert r["launch_status"] == 0 and r["processes"] == names
    assert r["ended"] == {name: ["has finished cleanly", 0] for name in names}
    assert r["error_lines"] == []
    assert _closed(tmp_path / "replayed")
