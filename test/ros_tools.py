"""Shared plumbing of the tests: waiting on conditions, a client node over DDS."""

from contextlib import contextmanager
import time
from typing import Iterator, Tuple

from pattern_locator.nodes.node_process import locator_process

__all__ = ['client_node', 'locator_process', 'spin_until', 'wait_until']


def wait_until(condition, timeout: float = 3.0, step: float = 0.01) -> bool:
    """Poll ``condition`` until it holds or ``timeout`` seconds pass; return whether it did."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(step)
    return condition()


@contextmanager
def client_node(name: str) -> Iterator[Tuple[object, object]]:
    """Yield (node, executor) in a ROS context of their own; shut all down afterwards."""
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node(name, context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        yield node, executor
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=context)


def spin_until(executor, condition, timeout: float) -> bool:
    """Spin ``executor`` until ``condition()`` holds or ``timeout`` seconds pass."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
        if condition():
            return True
    return False
