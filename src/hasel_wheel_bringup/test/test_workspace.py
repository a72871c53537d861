"""Static consistency of the colcon workspace (runs without ROS): entry points, launch files,
package.xml dependencies, and rclpy kept out of the numerical core."""
import ast
import re
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[2]
PY_PACKAGES = ["hasel_wheel_common", "hasel_wheel_bag", "hasel_wheel_driver", "hasel_wheel_sim",
               "hasel_wheel_mpc", "hasel_wheel_ident", "hasel_wheel_bringup"]


def console_scripts(pkg):
    tree = ast.parse((SRC / pkg / "setup.py").read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.Dict):
            for k, v in zip(node.keys, node.values):
                if isinstance(k, ast.Constant) and k.value == "console_scripts":
                    return [e.value for e in v.elts]
    return []


@pytest.mark.parametrize("pkg", PY_PACKAGES)
def test_every_console_script_has_a_main(pkg):
    for entry in console_scripts(pkg):
        name, target = [x.strip() for x in entry.split("=")]
        module, func = target.split(":")
        path = SRC / pkg / (module.replace(".", "/") + ".py")
        assert path.is_file(), f"{entry}: no module file {path}"
        funcs = {n.name for n in ast.parse(path.read_text()).body if isinstance(n, ast.FunctionDef)}
        assert func in funcs, f"{entry}: {path} defines no {func}()"


@pytest.mark.parametrize("pkg", PY_PACKAGES + ["hasel_wheel_msgs"])
def test_package_xml_is_format_3_with_resource_marker(pkg):
    root = ET.parse(SRC / pkg / "package.xml").getroot()
    assert root.get("format") == "3" and root.findtext("name") == pkg
    if pkg != "hasel_wheel_msgs":
        assert (SRC / pkg / "resource" / pkg).is_file()
        assert root.find("export/build_type").text == "ament_python"


def test_launch_files_name_existing_executables():
    scripts = {p: {e.split("=")[0].strip() for e in console_scripts(p)} for p in PY_PACKAGES}
    launches = list(SRC.glob("*/launch/*.launch.py"))
    assert launches
    for f in launches:
        text = f.read_text()
        for pkg, exe in re.findall(r'package="([^"]+)",\s*executable="([^"]+)"', text):
            assert exe in scripts[pkg], f"{f.name}: {pkg} has no executable {exe}"


#: rosdep keys of the third-party modules the packages import.
ROSDEP = {"numpy": "python3-numpy", "scipy": "python3-scipy", "yaml": "python3-yaml",
          "serial": "python3-serial", "matplotlib": "python3-matplotlib", "tqdm": "python3-tqdm",
          "numba": "python3-numba", "pytest": "python3-pytest",
          "hypothesis": "python3-hypothesis", "launch_testing": "launch_testing"}
#: Imported, but with no rosdep key: pip-installed as docs/ros2.md says.
NO_ROSDEP_KEY = {"mcap", "mcap_ros2", "cobs", "rosbags"}
#: Imported only inside a try (the code runs without them): not dependencies.
OPTIONAL = {"pyarrow", "threadpoolctl", "zstandard"}


def test_imports_are_declared_in_package_xml():
    """Every import of a ROS package, a workspace package or a third-party module is a
    dependency in package.xml (a test's import may be a test_depend), so rosdep installs it."""
    ros_pkgs = {"rclpy", "std_msgs", "sensor_msgs", "diagnostic_msgs", "hasel_wheel_msgs",
                "rcl_interfaces", "launch", "launch_ros"}
    stdlib = set(sys.stdlib_module_names)
    checked = 0
    for pkg in PY_PACKAGES:
        root = ET.parse(SRC / pkg / "package.xml").getroot()
        deps = {e.text for e in root if e.tag.endswith("depend") and e.tag != "test_depend"}
        test_deps = deps | {e.text for e in root if e.tag == "test_depend"}
        for f in (SRC / pkg).rglob("*.py"):
            if "egg-info" in str(f) or f.name == "setup.py":
                continue
            have = test_deps if "test" in f.relative_to(SRC / pkg).parts else deps
            for node in ast.walk(ast.parse(f.read_text())):
                names = []
                if isinstance(node, ast.Import):
                    names = [a.name.split(".")[0] for a in node.names]
                elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                    names = [node.module.split(".")[0]]
                for n in names:
                    if n in stdlib or n in NO_ROSDEP_KEY | OPTIONAL or n == pkg:
                        continue
                    key = ROSDEP.get(n, n)
                    assert n in ros_pkgs | set(PY_PACKAGES) | set(ROSDEP), \
                        f"{f}: imports {n}, which has no rosdep key here (add it to ROSDEP)"
                    assert key in have, f"{f}: imports {n} but {pkg}/package.xml lacks {key}"
                    checked += 1
    assert checked > 50


def test_rclpy_only_in_node_and_launch_modules():
    for pkg in PY_PACKAGES:
        for f in (SRC / pkg).rglob("*.py"):
            rel = f.relative_to(SRC).as_posix()
            if re.search(r"(^|/)(nodes?/|launch/|test/)|_node\.py$|launch\.py$", rel):
                continue
            assert not re.search(r"^\s*(import rclpy|from rclpy)", f.read_text(), re.M), rel


def declared_parameters(pkg):
    """{name: default or None} of every declare_parameter("name", default, ...) in pkg's node
    modules (``*_node.py``, and ``node_*.py`` helpers that declare parameters for them)."""
    out = {}
    for f in [*(SRC / pkg).rglob("*_node.py"), *(SRC / pkg).rglob("node_*.py")]:
        for node in ast.walk(ast.parse(f.read_text())):
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                    and node.func.attr == "declare_parameter" and node.args
                    and isinstance(node.args[0], ast.Constant)):
                default = node.args[1] if len(node.args) > 1 else None
                out[node.args[0].value] = default.value if isinstance(default, ast.Constant) else None
    return out


@pytest.mark.parametrize("pkg", PY_PACKAGES)
def test_parameter_files_match_declared_parameters(pkg):
    """Every ros__parameters entry is declared by a node of the package, with the default's type
    (rclpy refuses an int for a double parameter, e.g. `gain: 0` for 0.0)."""
    import yaml
    declared = declared_parameters(pkg)
    for f in (SRC / pkg / "config").glob("*.yaml"):
        data = yaml.safe_load(f.read_text())
        if not isinstance(data, dict):
            continue
        for key, block in data.items():
            if not (isinstance(block, dict) and "ros__parameters" in block):
                continue
            for name, value in block["ros__parameters"].items():
                assert name in declared, f"{f.name}: {key}: {name} is declared by no {pkg} node"
                default = declared[name]
                if default is not None:
                    assert type(value) is type(default), \
                        f"{f.name}: {name} = {value!r}, but the node declares {default!r}"


def test_launch_files_name_existing_share_files():
    """Files a launch file names as [share, "config" | "launch", "file"] exist in some package."""
    launches = list(SRC.glob("*/launch/*.launch.py"))
    for f in launches:
        for sub, name in re.findall(r'"(config|launch)",\s*"([^"]+)"', f.read_text()):
            assert list(SRC.glob(f"*/{sub}/{name}")), f"{f.name}: no package has {sub}/{name}"
    # share_file_argument(name, package, file): <package>/config/<file>
    found = 0
    for f in [*launches, SRC / "hasel_wheel_bringup" / "hasel_wheel_bringup" / "launch_support.py"]:
        for pkg, name in re.findall(r'share_file_argument\(\s*"[^"]+",\s*"([^"]+)",\s*"([^"]+)"',
                                    f.read_text()):
            found += 1
            assert (SRC / pkg / "config" / name).is_file(), f"{f.name}: no {pkg}/config/{name}"
    assert found >= 5
