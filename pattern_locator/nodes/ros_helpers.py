"""Small helpers of the nodes: parameters with a description and a range, poses."""

import sys
from typing import Any, Callable, Dict, Iterable

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.node import Node

from ..errors import PatternLocatorError
from ..vision.geometry import Pose, quaternion_xyzw


def declare_number(node: Node, name: str, value: float, description: str,
                   low: float, high: float) -> None:
    """Declare a floating-point parameter limited to [low, high]."""
    node.declare_parameter(name, float(value), ParameterDescriptor(
        description=description,
        floating_point_range=[FloatingPointRange(from_value=float(low), to_value=float(high))]))


def declare_integer(node: Node, name: str, value: int, description: str,
                    low: int, high: int) -> None:
    """Declare an integer parameter limited to [low, high]."""
    node.declare_parameter(name, int(value), ParameterDescriptor(
        description=description,
        integer_range=[IntegerRange(from_value=int(low), to_value=int(high), step=1)]))


def declare_value(node: Node, name: str, value: Any, description: str) -> None:
    """Declare a parameter without a range (text, booleans, lists)."""
    node.declare_parameter(name, value, ParameterDescriptor(description=description))


def parameter_values(node: Node, names: Iterable[str]) -> Dict[str, Any]:
    """Return the current values of the named parameters."""
    return {name: node.get_parameter(name).value for name in names}


def fill_pose(msg: Any, T: Pose) -> None:
    """Write a Pose into a geometry_msgs/Pose."""
    msg.position.x, msg.position.y, msg.position.z = (float(v) for v in T.t)
    (msg.orientation.x, msg.orientation.y, msg.orientation.z,
     msg.orientation.w) = (float(v) for v in quaternion_xyzw(T.R))


def stamp_seconds(stamp: Any) -> float:
    """Return a builtin_interfaces/Time as seconds."""
    return stamp.sec + stamp.nanosec * 1e-9


def run_node(make_node: Callable[[], Node], name: str, args=None) -> None:
    """
    Spin a node until Ctrl-C; exit 1 with one line on stderr if it cannot start.

    The node's ``stop()`` (its threads, its ports) runs before the node is
    destroyed and ROS shut down.
    """
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    import rclpy

    rclpy.init(args=args)
    node = None
    code = 0
    try:
        node = make_node()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except PatternLocatorError as exc:
        print(f'{name}: error: {exc}', file=sys.stderr, flush=True)
        code = 1
    finally:
        if node is not None:
            node.stop()
            node.destroy_node()
        rclpy.try_shutdown()
    if code:
        sys.exit(code)
