"""
Small helpers of the nodes: parameters, throttled problem reports, clean start and stop.

* :class:`Param` describes one parameter (default, description, range or
  choices, and whether it may change at run time); :class:`Parameters`
  declares a node's list, refuses a bad value at start with one line, and
  validates and applies run-time changes through the node's own callbacks.
* :class:`ProblemLog` counts problems by kind and logs each kind at most
  every few seconds, foreign strings quoted and cut (:func:`quote`).
* :func:`run_node` spins a node until SIGINT or SIGTERM and shuts it down
  cleanly, however many signals follow.
"""

from dataclasses import dataclass
import gc
import math
import signal
import sys
import threading
import time
import traceback
from typing import Any, Callable, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple

from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                SetParametersResult)
from rclpy.node import Node

from ..errors import ConfigError, PatternLocatorError
from ..vision.geometry import Pose, quaternion_xyzw

# Cut foreign strings (encodings, frame ids, joint names, error texts) to this.
QUOTE_CHARS = 80
# A log line about bad input never exceeds this.
PROBLEM_CHARS = 240
# Problems are counted by at most this many kinds, 'other' included.
MAX_KINDS = 64


# Parameters ------------------------------------------------------------------------------


@dataclass(frozen=True)
class Param:
    """
    One node parameter.

    ``low``/``high``: the range of a number (a descriptor range, checked by
    ROS). ``choices``: the allowed strings (listed in the descriptor's
    ``additional_constraints``, checked by :class:`Parameters`). ``dynamic``:
    it may be set while the node runs; otherwise it is declared read-only.
    """

    name: str
    default: Any
    description: str
    low: Optional[float] = None
    high: Optional[float] = None
    choices: Tuple[str, ...] = ()
    dynamic: bool = False

    def descriptor(self) -> ParameterDescriptor:
        """Return the ROS descriptor: description, range, choices, read-only."""
        d = ParameterDescriptor(description=self.description, read_only=not self.dynamic)
        if self.low is not None and self.high is not None:
            if isinstance(self.default, bool) or not isinstance(self.default, (int, float)):
                raise TypeError(f'{self.name}: a range needs a numeric default')
            if isinstance(self.default, int):
                d.integer_range = [IntegerRange(from_value=int(self.low),
                                                to_value=int(self.high), step=1)]
            else:
                d.floating_point_range = [FloatingPointRange(from_value=float(self.low),
                                                             to_value=float(self.high))]
        constraints = []
        if self.choices:
            constraints.append('one of: ' + ', '.join(self.choices))
        constraints.append('can be set at run time' if self.dynamic else
                           'read-only: set at start (-p or a parameter file)')
        d.additional_constraints = '; '.join(constraints)
        return d

    def check(self, value: Any) -> Optional[str]:
        """Return why ``value`` is refused (choices, finiteness), or None."""
        if self.choices and value not in self.choices:
            return (f'{self.name} must be one of {", ".join(self.choices)}, got '
                    f'{quote(value)}')
        if isinstance(value, float) and not math.isfinite(value):
            return f'{self.name} must be a finite number, got {value}'
        return None


class Parameters:
    """
    A node's parameters: declared at start, validated and applied at run time.

    ``validate(values)`` gets every parameter's value as it would be after a
    change and returns why it is refused (None: accepted); it should build
    whatever the change builds (e.g. the tracking settings), so that what it
    accepts is known to work. ``apply(changed)`` gets the changed
    parameters' new values after ROS stored them. Both run on the executor
    thread.
    """

    def __init__(self, node: Node, specs: Sequence[Param]) -> None:
        self.node = node
        self.specs: Dict[str, Param] = {s.name: s for s in specs}
        self._validate: Optional[Callable[[Dict[str, Any]], Optional[str]]] = None
        self._apply: Optional[Callable[[Dict[str, Any]], None]] = None
        for spec in specs:
            try:
                node.declare_parameter(spec.name, spec.default, spec.descriptor())
            except Exception as exc:  # noqa: B902 - rclpy's ParameterException and kin
                raise ConfigError(_start_error(spec, exc)) from None
        for spec in specs:
            problem = spec.check(node.get_parameter(spec.name).value)
            if problem:
                raise ConfigError(f'parameter {problem}')

    @property
    def names(self) -> Tuple[str, ...]:
        """Return the parameter names in declaration order."""
        return tuple(self.specs)

    def values(self) -> Dict[str, Any]:
        """Return every parameter's current value."""
        return {name: self.node.get_parameter(name).value for name in self.specs}

    def check_all(self, validate: Callable[[Dict[str, Any]], Optional[str]]) -> None:
        """Run ``validate`` on the start values; ConfigError with its reason if refused."""
        problem = validate(self.values())
        if problem:
            raise ConfigError(problem)

    def on_change(self, validate: Callable[[Dict[str, Any]], Optional[str]],
                  apply: Callable[[Dict[str, Any]], None]) -> None:
        """Accept run-time changes that ``validate`` allows, then ``apply`` them."""
        self._validate, self._apply = validate, apply
        self.node.add_on_set_parameters_callback(self._on_set)
        self.node.add_post_set_parameters_callback(self._on_post_set)

    def _on_set(self, parameters: List[Any]) -> SetParametersResult:
        changed = {p.name: p.value for p in parameters if p.name in self.specs}
        for name, value in changed.items():
            problem = self.specs[name].check(value)
            if problem:
                return SetParametersResult(successful=False, reason=problem)
        if self._validate is not None and changed:
            values = self.values()
            values.update(changed)
            try:
                problem = self._validate(values)
            except PatternLocatorError as exc:
                problem = str(exc)
            if problem:
                return SetParametersResult(successful=False, reason=problem)
        return SetParametersResult(successful=True)

    def _on_post_set(self, parameters: List[Any]) -> None:
        changed = {p.name: p.value for p in parameters if p.name in self.specs}
        if changed and self._apply is not None:
            self._apply(changed)
            self.node.get_logger().info('parameters set: ' + ', '.join(
                f'{k}={quote(v)}' for k, v in sorted(changed.items())))


def _start_error(spec: Param, exc: Exception) -> str:
    """Return one line for a value ROS refused at declaration."""
    text = str(exc)
    suffix = f': {spec.name}'
    if text.endswith(suffix):
        text = text[:-len(suffix)]
    if "of type 'INTEGER', expecting type 'DOUBLE'" in text:
        text += ' (write a double, e.g. 10.0)'
    return f'parameter {spec.name}: {_cut(text, PROBLEM_CHARS)}'


def parameter_values(node: Node, names: Iterable[str]) -> Dict[str, Any]:
    """Return the current values of the named parameters."""
    return {name: node.get_parameter(name).value for name in names}


# Problems and their log ------------------------------------------------------------------


def _cut(text: str, limit: int) -> str:
    if len(text) <= limit:
        return text
    return f'{text[:limit]}... ({len(text)} characters)'


def quote(value: Any, limit: int = QUOTE_CHARS) -> str:
    """Return a foreign value quoted (``repr``: control characters escaped) and cut."""
    if isinstance(value, (bytes, bytearray, memoryview)):
        value = bytes(value[:limit * 2])
    text = repr(value)
    return _cut(text, limit)


def clean_text(text: str, limit: int = PROBLEM_CHARS) -> str:
    """Return a log line's text on one line (control characters escaped) and cut."""
    text = str(text)
    if not text.isprintable():
        text = ''.join(c if c.isprintable() else repr(c)[1:-1] for c in text[:limit * 2])
    return _cut(text, limit)


class ProblemLog:
    """
    Count problems by kind; log each kind at most every ``period_s``.

    A kind is a short fixed name ('image', 'camera_info', 'joint_states',
    'localizer', ...), never a foreign string, so garbage of endless variety
    still gives one line per kind and period; the line says how many were
    not logged. Thread-safe.
    """

    def __init__(self, logger: Any, period_s: float = 5.0) -> None:
        self.logger = logger
        self.period_s = period_s
        self.counts: Dict[str, int] = {}
        self.last: Dict[str, str] = {}
        self.last_text = ''
        self._logged_at: Dict[str, float] = {}
        self._unlogged: Dict[str, int] = {}
        self._lock = threading.Lock()

    def report(self, kind: str, text: str) -> None:
        """Count a problem of ``kind``; log it unless this kind was logged lately."""
        text = clean_text(text)
        with self._lock:
            if kind not in self.counts and len(self.counts) >= MAX_KINDS - 1:
                kind = 'other'
            self.counts[kind] = self.counts.get(kind, 0) + 1
            self.last[kind] = text
            self.last_text = text
            now = time.monotonic()
            due = now - self._logged_at.get(kind, -math.inf) >= self.period_s
            if due:
                self._logged_at[kind] = now
                skipped = self._unlogged.pop(kind, 0)
            else:
                self._unlogged[kind] = self._unlogged.get(kind, 0) + 1
        if due:
            more = (f" ({skipped} more '{kind}' problems since the last report)" if skipped
                    else '')
            self.logger.warning(f'{text}{more}')

    def snapshot(self) -> Tuple[Dict[str, int], str]:
        """Return (counts by kind, the last problem's text)."""
        with self._lock:
            return dict(self.counts), self.last_text


# Messages --------------------------------------------------------------------------------


def fill_pose(msg: Any, T: Pose) -> None:
    """Write a Pose into a geometry_msgs/Pose."""
    msg.position.x, msg.position.y, msg.position.z = (float(v) for v in T.t)
    (msg.orientation.x, msg.orientation.y, msg.orientation.z,
     msg.orientation.w) = (float(v) for v in quaternion_xyzw(T.R))


def stamp_seconds(stamp: Any) -> float:
    """Return a builtin_interfaces/Time as seconds."""
    return stamp.sec + stamp.nanosec * 1e-9


def stamp_key(stamp: Any) -> int:
    """Return a builtin_interfaces/Time as integer nanoseconds (a dictionary key)."""
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def head_motion_to_point(x: float, y: float, z: float) -> Tuple[float, float]:
    """
    Return the pan and tilt turns (rad, REP 103) that put a point on the optical axis.

    The point is in ``camera_optical_frame`` (x right, y down, z forward);
    pan positive turns left, tilt positive looks up.
    """
    return -math.atan2(x, z), -math.atan2(y, math.hypot(x, z))


def all_finite(values: Iterable[float]) -> bool:
    """Return whether every value is a finite number."""
    try:
        return all(math.isfinite(float(v)) for v in values)
    except (TypeError, ValueError):
        return False


def wall_timer(node: Node, period_s: float, callback: Callable[[], None]) -> Any:
    """
    Create a timer on the steady clock: it fires whatever the ROS time does.

    For diagnostics and other housekeeping: with ``use_sim_time`` and no
    ``/clock`` (a bag replayed without it) a ROS-time timer never fires.
    """
    from rclpy.clock import Clock, ClockType
    return node.create_timer(period_s, callback, clock=Clock(clock_type=ClockType.STEADY_TIME))


def declared_parameters(specs: Sequence[Param]) -> Tuple[str, ...]:
    """Return the names of a node's parameter list (what its YAML file must name)."""
    return tuple(s.name for s in specs)


def describe_values(values: Mapping[str, Any], width: int = 400) -> List[str]:
    """
    Return ``name=value, ...`` for a node's start-up log, as lines of at most ``width``.

    Sorted by name; an entry longer than a line (a long path) is cut with
    '...': the log's lines stay short however many parameters a node has.
    """
    lines: List[str] = []
    line = ''
    for k, v in sorted(values.items()):
        entry = f'{k}={v}'
        if len(entry) > width:
            entry = entry[:width - 3] + '...'
        if line and len(line) + 2 + len(entry) > width:
            lines.append(line)
            line = ''
        line = f'{line}, {entry}' if line else entry
    if line or not lines:
        lines.append(line)
    return lines


# Running a node -------------------------------------------------------------------------


def _ignore_signals() -> None:
    """Ignore SIGINT and SIGTERM from now on: shutting down is already under way."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        try:
            signal.signal(sig, signal.SIG_IGN)
        except (ValueError, OSError):      # not the main thread
            pass


def failed_take(exc: BaseException) -> bool:
    """Tell whether ``exc`` was raised while rclpy's executor took a message from DDS."""
    frames = traceback.extract_tb(exc.__traceback__)
    return any(f.name.startswith('_take_')
               and f.filename.replace('\\', '/').endswith('rclpy/executors.py') for f in frames)


def run_node(make_node: Callable[[], Node], name: str, args=None) -> None:
    """
    Spin a node until SIGINT or SIGTERM; exit 1 with one line on stderr if it cannot start.

    rclpy's signal handlers wake the executor on the first SIGINT or SIGTERM;
    from then on both signals are ignored, so a second Ctrl-C (``ros2
    launch`` sends one to the process group while the nodes shut down) or a
    SIGTERM cannot interrupt the clean-up: the exit status is 0 and nothing
    is printed. The node's ``stop()`` (its threads, its ports) runs before
    the node is destroyed and ROS shut down.
    """
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    import rclpy

    code = 0
    node = None
    try:
        rclpy.init(args=args)
        try:
            node = make_node()
            # The start-up's objects (rclpy, the building map, the detector's
            # tables) out of the cyclic collector: its full collections then
            # scan only what the frames made since. A full collection over a
            # heap like the stress bench's took 15-41 ms, a frame's time
            # several times over.
            gc.freeze()
            executor = SingleThreadedExecutor()
            executor.add_node(node)
            failed_takes = 0
            while True:
                try:
                    executor.spin()
                    break
                except RuntimeError as exc:
                    # A message DDS delivered that rclpy could not turn into
                    # a Python message (seen once in a test, while the nodes
                    # that publish to the locator were being stopped): that
                    # message is lost, the node is not.
                    if not rclpy.ok() or not failed_take(exc):
                        raise
                    failed_takes += 1
                    node.get_logger().warning(
                        f'a message could not be taken ({clean_text(str(exc), 200)}); '
                        f'{failed_takes} so far', throttle_duration_sec=5.0)
        except (KeyboardInterrupt, ExternalShutdownException):
            _ignore_signals()
        except PatternLocatorError as exc:
            _ignore_signals()
            print(f'{name}: error: {clean_text(str(exc), 400)}', file=sys.stderr, flush=True)
            code = 1
        except Exception:  # noqa: B902 - see below
            # A signal shuts the context down at once, also under a callback
            # that is still running: its next publish fails. That is the
            # shutdown, not an error; anything else is.
            if rclpy.ok():
                raise
            _ignore_signals()
        finally:
            _ignore_signals()
            if node is not None:
                node.stop()
                node.destroy_node()
            rclpy.try_shutdown()
            # try_shutdown restores the handlers rclpy replaced: ignore again.
            _ignore_signals()
    except KeyboardInterrupt:
        # A signal before the handlers were replaced (during init): a clean exit all the same.
        _ignore_signals()
    if code:
        sys.exit(code)
