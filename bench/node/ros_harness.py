"""What the node benchmarks share: a private DDS domain for the node process and a client node in it.

Each benchmark run gets its own ``ROS_DOMAIN_ID`` (from the process id and a per-script salt, so parallel
runs never mix) with discovery limited to this host; the node subprocess gets it through ``env`` and the
client in this process through ``os.environ`` and :func:`client`.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any


def private_domain(tmp: Path, salt: int, offset: int = 0) -> tuple[int, dict[str, str]]:
    """Return ``(domain id, environment for the node subprocess)``; this process joins the domain too."""
    domain = 1 + (os.getpid() * salt + offset) % 100
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               ROS_LOG_DIR=str(tmp / "ros_log"), ROS_HOME=str(tmp / "ros_home"), PYTHONUNBUFFERED="1")
    os.environ.update({k: env[k] for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_LOG_DIR")})
    return domain, env


def client(domain: int, name: str) -> tuple[Any, Any, Any]:
    """Return ``(context, node, executor)``: a client node spun by its own single-threaded executor."""
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node

    context = Context()
    rclpy.init(context=context, domain_id=domain)
    node = Node(name, context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    return context, node, executor
