"""The configuration a ROS launch records with ``ros2 bag record --custom-data``."""
import hashlib

import pytest
import yaml

from hasel_wheel_mpc.recorder import launch_custom_data


def _as_jazzy_parses(pairs):
    """ros2bag/verb/record.py (jazzy): ``pair.split('=')``, then ``{pair[0]: pair[1]}``."""
    key_value_pairs = [pair.split("=") for pair in pairs]
    return {pair[0]: pair[1] for pair in key_value_pairs}


def test_files_survive_jazzy_s_key_value_split(tmp_path):
    plain = tmp_path / "mpc.yaml"
    plain.write_text("mpc_node:\n  ros__parameters:\n    reference_speed: 1.5\n")
    commented = tmp_path / "observer.yaml"
    commented.write_text("# gain K = 0.1\nobserver_node:\n  ros__parameters: {gain: 0.1}\n")
    tricky = tmp_path / "notes.yaml"
    tricky.write_text("note: a = b\n")
    custom = launch_custom_data([str(plain), str(commented), str(tricky)],
                                {"tool": "sim_closed_loop"})
    assert custom["file:mpc.yaml"] == plain.read_text()
    assert yaml.safe_load(custom["file:observer.yaml"]) == yaml.safe_load(commented.read_text())
    digest = hashlib.sha256(tricky.read_bytes()).hexdigest()
    assert custom["file:notes.yaml"] == f"{tricky.resolve()} sha256 {digest}"
    assert custom["tool"] == "sim_closed_loop" and custom["git_revision"]
    from importlib import metadata
    assert f"hasel_wheel_mpc {metadata.version('hasel_wheel_mpc')}" in custom["packages"]
    assert _as_jazzy_parses([f"{k}={v}" for k, v in custom.items()]) == custom


def test_an_equals_sign_in_extra_data_is_refused():
    with pytest.raises(ValueError, match="must not contain '='"):
        launch_custom_data([], {"a": "b=c"})
