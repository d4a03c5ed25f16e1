"""``~/save`` served by a hidden helper node in a thread of its own, so its wait blocks no learning.

The reply waits for the checkpoint file
(:meth:`~semiparam_ros.serving.checkpoint_writer.CheckpointWriter.save`); served from the node's own executor,
that wait would stall learning (and needs a coroutine, which the ``EventsExecutor`` never awaits). The service
name is resolved with the node's remappings; the helper (``_<name>_save``, no parameter services, no rosout)
takes it as is.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from std_srvs.srv import Trigger

__all__ = ["SaveService"]


class SaveService:
    """Serve ``~/save`` of ``node`` from a helper node spun in a daemon thread.

    Args:
        node: The node whose ``~/save`` this is (name, namespace, context, remappings).
        save: Writes the checkpoint and returns ``(ok, message)`` (called in the helper's thread).
        join_timeout_s: How long :meth:`close` waits for the thread.
    """

    def __init__(self, node: Node, save: Callable[[], tuple[bool, str]], *, join_timeout_s: float) -> None:
        self._save = save
        self._join_timeout_s = join_timeout_s
        self._node = Node(f"_{node.get_name()}_save", namespace=node.get_namespace(), context=node.context,
                          use_global_arguments=False, start_parameter_services=False, enable_rosout=False)
        self._node.create_service(Trigger, node.resolve_service_name("~/save"), self._on_save)
        self._executor: SingleThreadedExecutor | None = SingleThreadedExecutor(context=node.context)
        self._executor.add_node(self._node)
        self._thread = threading.Thread(target=self._spin, name="estimator-save", daemon=True)
        self._thread.start()

    def _on_save(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        response.success, response.message = self._save()
        return response

    def _spin(self) -> None:
        executor = self._executor
        if executor is None:
            return
        try:
            executor.spin()
        except ExternalShutdownException:
            pass

    def close(self) -> None:
        """Stop the thread and destroy the helper node (idempotent)."""
        executor, self._executor = self._executor, None
        if executor is None:
            return
        executor.shutdown(timeout_sec=1.0)
        self._thread.join(timeout=self._join_timeout_s)
        self._node.destroy_node()
