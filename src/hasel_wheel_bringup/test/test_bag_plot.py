"""bag plot: the force recovered from a recorded motion against the force law that made it,
and the figures of a recorded run."""
import math

import numpy as np
import pytest

from hasel_wheel_bag.layout import BagError
from hasel_wheel_bringup.bag_cli import main as bag_main
from hasel_wheel_bringup.bag_plot import _collect, force_samples, raw_encoder_speed
from hasel_wheel_mpc.recorder import Recorder
from hasel_wheel_bringup.trials import TrialSpec, run_trial
from hasel_wheel_sim.model import force_law, param_vector
from hasel_wheel_sim.params import WheelParams
from hasel_wheel_sim.plant import PlantConfig

PHI_A = math.radians(5.0)


@pytest.fixture(scope="module")
def open_loop_bag(tmp_path_factory):
    """20 s open loop at phi_a = 5 deg on the paper's model (no effects), recorded."""
    path = tmp_path_factory.mktemp("plot") / "run"
    rec = Recorder(path)
    run_trial(TrialSpec(PHI_A, math.radians(22.0), duration=20.0), WheelParams(),
              PlantConfig(switching="exact"), rec, "/w0")
    rec.close()
    return path


def test_the_force_recovered_from_the_true_motion_is_the_force_law(open_loop_bag):
    """Inverting the flow map on the recorded true state gives back (43) wherever the
    actuator is on (central differences at 300 Hz: away from the switch instants)."""
    d = _collect(open_loop_bag, progress=False)["/w0"]
    tel, true = d["tel"], d["true"]
    assert np.array_equal(tel["t"], true["t"])
    xc, f = force_samples(tel["t"], true["xi1"], true["xi2"], tel["q"], tel["eta_u"],
                          WheelParams(), smooth=False)
    pv = param_vector(WheelParams())
    on = tel["q"] == 1
    model = np.array([force_law(x, v, PHI_A, pv) for x, v in zip(xc, true["xi2"][on])])
    inner = (xc > PHI_A + 0.01) & (xc < math.radians(21.0))      # two samples from a switch
    assert inner.sum() > 500
    rel = np.abs(f[inner] - model[inner]) / np.abs(model[inner]).max()
    assert np.median(rel) < 0.01 and np.percentile(rel, 95) < 0.05


def test_raw_encoder_speed_is_the_finite_difference():
    t = np.arange(5) / 300
    angle = np.array([0.0, 1, 3, 6, 10]) * (2 * math.pi / 1024)
    v = raw_encoder_speed(t, angle)
    assert v[1:] == pytest.approx(np.array([1, 2, 3, 4]) * 2 * math.pi / 1024 * 300)
    assert v[0] == v[1]


def test_the_command_writes_four_pngs_per_wheel(open_loop_bag, tmp_path, capsys):
    assert bag_main(["plot", str(open_loop_bag), "--out", str(tmp_path / "png")]) == 0
    names = sorted(p.name for p in (tmp_path / "png").iterdir())
    assert names == ["w0_force.png", "w0_observer.png", "w0_raster.png", "w0_speed.png"]
    for n in names:
        assert (tmp_path / "png" / n).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert bag_main(["plot", str(open_loop_bag), "--out", str(tmp_path / "x"),
                     "--namespace", "/nope"]) == 2
    assert "nothing to plot: no telemetry under ['/nope']" in capsys.readouterr().err


def test_plot_of_a_bag_without_wheels_is_a_clear_error(tmp_path):
    from hasel_wheel_common import topics
    from hasel_wheel_bag.writer import BagWriter
    from hasel_wheel_bringup.bag_plot import plot_bag
    with BagWriter(tmp_path / "b") as b:
        b.add_topic("/r", topics.REFERENCE.type, topics.REFERENCE.qos)
        b.write("/r", {"data": 1.0}, 0)
    with pytest.raises(BagError, match="nothing to plot"):
        plot_bag(tmp_path / "b", tmp_path / "o")
