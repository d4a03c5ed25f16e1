"""docs/node.md lists exactly what a started node creates on the ROS graph (topics, services, actions, with
their types and QoS), for a joint-torque arm and an F/T sensor: the table is rendered from the graph of
nodes started here and compared with the committed page."""

from __future__ import annotations

import pytest
from helpers.ros import make_ros_env

from docs.tools.node_reference import BEGIN, END, PAGE, node_table, render_page

pytestmark = pytest.mark.ros


def test_node_reference_lists_every_interface_of_a_started_node(tmp_path, monkeypatch):
    make_ros_env(tmp_path, monkeypatch)  # ROS_HOME, logs and discovery of this test only
    text = PAGE.read_text(encoding="utf-8")
    table = node_table()
    for name in ("`~/follow_joint_trajectory`", "`~/predicted_wrench`", "`~/predicted_joint_torques`",
                 "`~/save`", "`joint_states`"):
        assert name in table  # the graph was read (an empty graph would render an empty table)
    committed = text[text.index(BEGIN) + len(BEGIN): text.index(END)].strip()
    stale = "docs/node.md is stale: run .venv/bin/python -m docs.tools.node_reference"
    assert committed == table.strip(), stale
    assert render_page(text, table) == text
