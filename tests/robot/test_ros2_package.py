"""The ROS 2 package's pieces agree with each other and with the session they wrap.

ROS 2 cannot be installed on the test machines, so the node is not run here (its README says so);
what can be checked without rclpy is: every file parses, the console script names a function that
exists, every ROS package the node and the launch file import is declared in package.xml, the
params YAML sets exactly the node's parameters, and the planner the parameters name builds.
"""

from __future__ import annotations

import ast
import xml.etree.ElementTree as ElementTree
from pathlib import Path

import yaml
from import_graph import ROOT

PACKAGE = ROOT / "ros2" / "guide_ros"
PYTHON_ONLY = {"json", "math", "os", "typing", "glob", "setuptools", "__future__", "pipeline"}


def parsed(path: Path) -> ast.Module:
    return ast.parse(path.read_text(), filename=str(path))


def imported_packages(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(parsed(path)):
        if isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module.split(".")[0])
        elif isinstance(node, ast.Import):
            names.update(alias.name.split(".")[0] for alias in node.names)
    return names - PYTHON_ONLY - {"guide_ros"}


def test_the_manifest_declares_every_ros_package_the_node_and_launch_file_import():
    manifest = ElementTree.parse(PACKAGE / "package.xml").getroot()
    assert manifest.findtext("name") == "guide_ros"
    assert manifest.find("export/build_type").text == "ament_python"
    declared = {element.text for element in manifest.findall("exec_depend")}
    used = imported_packages(PACKAGE / "guide_ros" / "explorer.py") | imported_packages(
        PACKAGE / "launch" / "explore.launch.py"
    )
    assert used <= declared, used - declared


def test_the_console_script_names_the_nodes_main():
    setup = (PACKAGE / "setup.py").read_text()
    assert "explorer = {PACKAGE}.explorer:main" in setup and (PACKAGE / "resource" / "guide_ros").exists()
    functions = {
        node.name for node in parsed(PACKAGE / "guide_ros" / "explorer.py").body if isinstance(node, ast.FunctionDef)
    }
    assert "main" in functions
    parsed(PACKAGE / "launch" / "explore.launch.py")


def node_parameters() -> dict:
    module = parsed(PACKAGE / "guide_ros" / "explorer.py")
    for node in module.body:
        if isinstance(node, ast.Assign) and getattr(node.targets[0], "id", "") == "PARAMETERS":
            return ast.literal_eval(node.value)
    raise AssertionError("explorer.py has no PARAMETERS")


def test_the_params_file_sets_exactly_the_nodes_parameters_with_their_defaults_types():
    parameters = node_parameters()
    config = yaml.safe_load((PACKAGE / "config" / "guide.yaml").read_text())["guide_explorer"]["ros__parameters"]
    assert set(config) == set(parameters)
    for name, value in config.items():
        assert type(value) is type(parameters[name]), name  # ROS 2 refuses a parameter that changes type


def test_the_configured_planner_and_protocol_make_a_session():
    from pipeline.planners.specs import build_planner, resolve_planner_specs
    from pipeline.robot import ExplorationSession

    config = yaml.safe_load((PACKAGE / "config" / "guide.yaml").read_text())["guide_explorer"]["ros__parameters"]
    (spec,) = resolve_planner_specs([config["planner"]])
    session = ExplorationSession(
        build_planner(spec),
        config["protocol"],
        seed=config["seed"],
        goal_tolerance_m=config["goal_tolerance_m"],
        replan_changed_cells=config["replan_changed_cells"],
        replan_after_s=config["replan_after_s"],
    )
    assert session.protocol.node_resolution == 1.0
