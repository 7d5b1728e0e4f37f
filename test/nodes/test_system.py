"""
The camera side over DDS: camera_driver on the emulated EVI-D31, the closed loop, the demo.

Real processes (``python -m pattern_locator.<node>``) and a real
pseudo-terminal; each run in the test session's own ROS domain.
"""

import math
from pathlib import Path
import re
import subprocess
import sys
import time

from diagnostic_msgs.msg import DiagnosticStatus
import numpy as np
from pattern_locator.evaluation.demo_system import camera_errors, run_closed_loop, stop_of
from pattern_locator.nodes.node_process import node_process
from pattern_locator.sim.world import RouteStop, SimRoute
from pattern_locator.visca.emulator import EmulatedEviD31
from pattern_locator.vision.geometry import Pose
import pytest
from ros_tools import client_node, spin_until


@pytest.fixture
def ros_node():
    with client_node('system_test') as pair:
        yield pair


def target_point(pan_error: float, tilt_error: float, distance: float = 3.0):
    """Return the optical-frame point (m) whose centring needs these head turns (REP 103)."""
    horizontal = distance * math.cos(tilt_error)
    return (-math.sin(pan_error) * horizontal, -math.sin(tilt_error) * distance,
            math.cos(pan_error) * horizontal)


def test_camera_driver_drives_the_emulated_camera_and_survives_faults(tmp_path, ros_node):
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import PointStamped
    from rclpy.qos import QoSProfile
    from pattern_locator.nodes.image_codec import fill_camera_info
    from pattern_locator.vision.camera import CameraModel
    from sensor_msgs.msg import CameraInfo, JointState
    from std_srvs.srv import Trigger
    from test_locator_node import ParameterClient

    node, executor = ros_node
    joints, diagnostics = [], []
    # A default-QoS (reliable) subscriber, like robot_state_publisher's.
    node.create_subscription(JointState, 'camera/joint_states', joints.append,
                             QoSProfile(depth=10))
    node.create_subscription(DiagnosticArray, '/diagnostics', diagnostics.append, 10)
    targets = node.create_publisher(PointStamped, 'pattern_locator/target', 10)
    link = tmp_path / 'evi_d31'
    with EmulatedEviD31(init_s=0.3, link_path=str(link)) as camera, \
            node_process('camera_driver_node', tmp_path / 'driver.log',
                         [f'port:={link}', 'search:=false']) as driver:
        assert spin_until(executor, lambda: len(joints) >= 5, 30.0), driver.log.read_text()
        assert list(joints[-1].name) == ['camera_pan', 'camera_tilt', 'camera_zoom']

        # Track a card 0.3 rad to the left and 0.1 rad up, given like the
        # locator does: its centre in the optical frame of "the image", stamped then.
        info_pub = node.create_publisher(CameraInfo, 'camera/camera_info', 10)

        def aim(pan_goal, tilt_goal, seconds, info=None, until=None):
            # Targets for ``seconds``, or until ``until()`` holds (the checks
            # below still decide: a head that never gets there fails them).
            end = time.monotonic() + seconds
            while time.monotonic() < end and not (until is not None and until()):
                state = camera.state()
                msg = PointStamped()
                msg.header.stamp = node.get_clock().now().to_msg()
                if info is not None:
                    info.header.stamp = msg.header.stamp
                    info_pub.publish(info)
                msg.header.frame_id = 'camera_optical_frame'
                msg.point.x, msg.point.y, msg.point.z = target_point(
                    pan_goal + math.radians(state.pan_deg),      # REP 103: left = +
                    tilt_goal - math.radians(state.tilt_deg))
                targets.publish(msg)
                spin_until(executor, lambda: False, 0.1)

        assert spin_until(executor, lambda: node.count_subscribers(
            '/pattern_locator/target') > 0, 10.0)

        def at(pan_goal, tilt_goal):
            # The head and its last joint state both within 0.5 deg of the goal.
            state = camera.state()
            return (joints and abs(-math.radians(state.pan_deg) - pan_goal) < math.radians(0.5)
                    and abs(math.radians(state.tilt_deg) - tilt_goal) < math.radians(0.5)
                    and abs(joints[-1].position[0] - pan_goal) < math.radians(0.5)
                    and abs(joints[-1].position[1] - tilt_goal) < math.radians(0.5))

        aim(0.3, 0.1, 3.0, until=lambda: at(0.3, 0.1))
        state = camera.state()
        assert state.pan_deg == pytest.approx(-math.degrees(0.3), abs=1.0)   # VISCA: right = +
        assert state.tilt_deg == pytest.approx(math.degrees(0.1), abs=1.0)
        last = joints[-1]
        assert last.position[0] == pytest.approx(0.3, abs=math.radians(1.0))
        assert last.position[1] == pytest.approx(0.1, abs=math.radians(1.0))
        # Targets stop: the head stops (hold) instead of running on.
        spin_until(executor, lambda: False, 1.0)
        held = camera.state().pan_deg
        spin_until(executor, lambda: False, 0.5)
        assert camera.state().pan_deg == pytest.approx(held, abs=0.2)

        # Parameters at run time: refused with the reason, or applied.
        params = ParameterClient(node, executor, '/camera_driver')
        ok, reason = params.set_value('target_timeout_s', 5.0)     # above search_after_s
        assert not ok and 'search_after_s' in reason, reason
        ok, reason = params.set_value('port', '/dev/ttyUSB7')
        assert not ok and 'read-only' in reason.lower()
        assert params.description('gain').floating_point_range[0].to_value == 20.0
        assert params.set_value('tracking', False) == (True, '')
        aim(-0.2, 0.0, 1.0)
        assert camera.state().pan_deg == pytest.approx(held, abs=0.2), 'tracking is off'
        assert params.set_value('tracking', True) == (True, '')
        aim(-0.2, 0.0, 2.5, until=lambda: at(-0.2, 0.0))
        assert camera.state().pan_deg == pytest.approx(math.degrees(0.2), abs=1.0)
        assert spin_until(executor, lambda: diagnostics and diagnostics[-1].status[0].level
                          == DiagnosticStatus.OK, 3.0), diagnostics[-1].status[0].message
        # Zoom: the card's apparent size comes from its distance and the fx of
        # the target's camera_info: 3 m at fx 554 px is 21 px, under the 120
        # px aimed at, so the camera zooms in.
        info = CameraInfo()
        fill_camera_info(info, CameraModel.from_fov(640, 480, 60.0))
        zoom = camera.state().zoom_units
        assert params.set_value('zoom_control', True)[0]
        aim(-0.2, 0.0, 2.0, info, until=lambda: camera.state().zoom_units > zoom + 100)
        assert camera.state().zoom_units > zoom + 100, (zoom, camera.state())
        assert params.set_value('zoom_control', False)[0]
        # A card behind the image plane (the gaze planner's handover to a card
        # more than 90 deg off the axis, z < 0): the head turns to it.
        aim(1.6, 0.0, 3.0, until=lambda: at(1.6, 0.0))
        assert camera.state().pan_deg == pytest.approx(-math.degrees(1.6), abs=1.0)

        # Garbage on the line and a Network Change: joint states keep coming.
        camera.send_garbage(bytes([0x00, 0x13, 0x0D, 0x90, 0x41]))
        camera.send_network_change()
        count = len(joints)
        assert spin_until(executor, lambda: len(joints) >= count + 10, 10.0)

        # The port vanishes: diagnostics leave OK; it comes back at the same
        # path: the driver recovers.
        camera.vanish()
        assert spin_until(executor, lambda: diagnostics[-1].status[0].level
                          != DiagnosticStatus.OK, 5.0)
        camera.restore()
        count = len(joints)
        assert spin_until(executor, lambda: len(joints) >= count + 10, 20.0), \
            driver.log.read_text()
        values = {kv.key: kv.value for kv in diagnostics[-1].status[0].values}
        assert int(values['connection losses']) >= 1
        assert values['ready'] == 'True'

        # ~/home brings the head back to 0.
        client = node.create_client(Trigger, '/camera_driver/home')
        assert client.wait_for_service(timeout_sec=10.0)
        future = client.call_async(Trigger.Request())
        assert spin_until(executor, future.done, 20.0)
        assert future.result().success, future.result().message
        state = camera.state()
        assert abs(state.pan_deg) < 0.2 and abs(state.tilt_deg) < 0.2
        assert driver.poll() is None
    text = driver.log.read_text()
    assert 'Traceback' not in text, text


def _tracking_errors(frames, route):
    phases = {'first': [], 'settled': [], 'driving': [], 'last': []}
    stamps = sorted(k for k, f in frames.items()
                    if f.true_target is not None and f.true_base is not None)
    for stamp in stamps:
        frame = frames[stamp]
        error = math.degrees(math.hypot(frame.true_target[0], frame.true_target[1]))
        index = stop_of(route, frame.true_base)
        phases['first' if index == 0 else 'driving' if index is None else 'last'].append(
            (stamp, error))
    return phases


def pass_by_card_route(dwell_s: float = 3.0) -> SimRoute:
    """Return 2 m along the wall 3 m from card 2 at 0.3 m/s; it starts 18 deg off-centre."""
    return SimRoute([RouteStop((2.0, 2.0), math.pi / 2, 2), RouteStop((4.0, 2.0), math.pi / 2, 2)],
                    mode='drive', dwell_s=dwell_s, speed_m_s=0.3)


def test_closed_loop_centres_the_card_and_keeps_it_centred_while_driving(tmp_path):
    route = pass_by_card_route()
    observer = run_closed_loop(tmp_path, route, timeout_s=60.0, custom_route=True)
    phases = _tracking_errors(observer.frames, route)
    first, driving = phases['first'], phases['driving']
    assert first and driving and phases['last'], {k: len(v) for k, v in phases.items()}
    # The head comes out of its power-up sweep at home with the card 18 deg
    # off, but the observer may join after the first frames, so the start is
    # not asserted here (bench --tracking measures the time to centre).
    settled = [e for s, e in first if s > first[-1][0] - 1.5e9]
    assert max(settled) < 1.0, settled                        # centred before it drives
    # The sim's robot goes from 0 to 0.3 m/s in an instant: the first half
    # second of the drive is that step's transient, then it must stay centred.
    cruising = [e for s, e in driving if s > driving[0][0] + 0.5e9]
    assert max(cruising) < 2.0, driving
    assert max(e for _, e in phases['last'][-10:]) < 1.0


def head_still(observer, stamp_ns: int, span_s: float = 0.2) -> bool:
    """Return whether the head stood still (within 0.1 deg) around an image's stamp."""
    t = stamp_ns * 1e-9
    try:
        angles = [observer.joints.at(t + dt) for dt in (-span_s, 0.0, span_s)]
    except Exception:  # noqa: B902 - no joint states around it: not known to be still
        return False
    return all(math.degrees(abs(a - b)) < 0.1 for p, q in zip(angles, angles[1:])
               for a, b in zip(p, q))


ROBOTS = {
    # namespace: (the robot's one stop, the card it faces 4 m away)
    'robot1': (RouteStop((4.0, 2.5), math.pi, 1), 1),
    'robot2': (RouteStop((6.0, 2.5), 0.0, 4), 4),
}


def test_two_namespaced_robots_side_by_side_on_one_domain(tmp_path):
    """Sim, driver and locator twice, in /robot1 and /robot2: each sees only its own."""
    from contextlib import ExitStack
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from pattern_locator.evaluation.demo_system import Observer, route_stops_parameter

    context = Context()
    rclpy.init(context=context)
    executor = SingleThreadedExecutor(context=context)
    observers = {ns: Observer(context, ns) for ns in ROBOTS}
    for observer in observers.values():
        executor.add_node(observer.node)
    try:
        with ExitStack() as stack:
            procs = []
            for ns, (stop, _) in ROBOTS.items():
                link = tmp_path / ns / 'evi_d31'
                route = SimRoute([stop], mode='stops', dwell_s=120.0)
                for module, parameters in (
                        ('sim_node', [f'camera_link:={link}', 'world:=paper', 'init_s:=0.3',
                                      'dwell_s:=120.0', route_stops_parameter(route)]),
                        ('camera_driver_node', [f'port:={link}', 'search:=false']),
                        ('locator_node', [])):
                    procs.append(stack.enter_context(node_process(
                        module, tmp_path / f'{ns}_{module}.log', parameters, ns)))

            def located(observer, still=False):
                return [f for stamp, f in observer.frames.items()
                        if f.located_base is not None and f.true_base is not None
                        and f.ids is not None and (not still or head_still(observer, stamp))]

            # Accuracy is judged on images taken with the head still (while it
            # turns, a loaded machine's late joint-state stamps cost degrees).
            assert spin_until(executor, lambda: all(len(located(o, still=True)) >= 3
                                                    for o in observers.values()), 60.0), \
                {ns: (len(located(o)), len(located(o, True))) for ns, o in observers.items()}
            assert all(p.poll() is None for p in procs)
            node = observers['robot1'].node
            topics = {name for name, _ in node.get_topic_names_and_types()}
            for ns in ROBOTS:
                for topic in ('robot_location', 'camera/image_raw', 'camera/joint_states',
                              'pattern_locator/target', 'sim/true_pose'):
                    assert f'/{ns}/{topic}' in topics, (ns, topic)
            # Nothing left in the root namespace but /diagnostics (and ROS's own).
            for topic in ('/robot_location', '/camera/image_raw', '/pattern_locator/target'):
                assert node.count_publishers(topic) == 0, topic
        for ns, observer in observers.items():
            card = ROBOTS[ns][1]
            frames = located(observer)
            # Each locator saw its own robot's card, never the other's, and
            # put its robot where its own sim says it is (the other robot is 2 m away).
            assert {f.ids for f in frames} == {(1, 3, card)}, (ns, {f.ids for f in frames})
            errors = [float(np.linalg.norm(f.located_base.t - f.true_base.t)) for f in frames]
            assert max(errors) < 0.5, (ns, errors)
            still = [float(np.linalg.norm(f.located_base.t - f.true_base.t))
                     for f in located(observer, still=True)]
            # A still head sees one image over and over, so the still fixes
            # share one error: that of the view where the head stopped. Over
            # 160 head angles within 1.5 deg of centring either card (zoom 0)
            # it was 1.5 cm in the median and at most 3.5 cm, against the
            # fixes' own 0.7-1.3 cm per axis; CI once saw 3.0 cm. Six nodes
            # share two cores here, and a single fix was once 6.1 cm off
            # beside two of 1.4 and 1.6 cm (fresh-clone CI): the median holds
            # the accuracy, the max only what a loaded machine's timing
            # allows (a joint or namespace mix-up would be tens of centimetres).
            assert float(np.median(still)) < 0.05 and max(still) < 0.10, (ns, still)
    finally:
        executor.shutdown()
        for observer in observers.values():
            observer.node.destroy_node()
        rclpy.shutdown(context=context)
    for path in tmp_path.glob('*.log'):
        assert 'Traceback' not in path.read_text(), path


def test_demo_runs_end_to_end_within_its_tolerance(tmp_path):
    out = tmp_path / 'out'
    proc = subprocess.run(
        # The demo's own dwell (2.5 s a stop): the sim starts the route once the
        # locator has found the first card (wait_for_target), not while DDS
        # discovery and the head's first search are still under way.
        [sys.executable, '-m', 'pattern_locator.cli', 'demo', '--route', 'paper-stops',
         '--stops', '4', '--dwell', '2.5', '--output-dir', str(out)], capture_output=True,
        text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    rows = re.findall(r'^\s+\d+\s+(\d+)\s+(?:[-\d.]+\s+){6}([\d.]+)\s+1/3/\d$', proc.stdout,
                      re.MULTILINE)
    assert len(rows) == 4, proc.stdout
    errors_cm = [float(e) for _, e in rows]
    # The README's tolerance: every stop within 5 cm, the mean within 2 cm.
    assert max(errors_cm) < 5.0 and sum(errors_cm) / 4 < 2.0, proc.stdout
    assert 'Table 1 avg' in proc.stdout
    plot = Path(re.search(r'plot of the true and located positions: (\S+)', proc.stdout)[1])
    assert plot.is_file() and plot.stat().st_size > 1000


def test_camera_errors_are_the_papers_quantities():
    card = Pose(np.eye(3), np.zeros(3))
    true = Pose(np.eye(3), np.array([0.0, 0.0, 2.0]))
    moved = Pose(np.eye(3), np.array([0.01, 0.0, 2.0]))
    errors = camera_errors(moved, true, card)
    assert errors['x (cm)'] == pytest.approx(1.0)
    assert errors['y (cm)'] == 0.0 and errors['z (cm)'] == 0.0
    assert errors['phi (deg)'] == pytest.approx(math.degrees(math.atan2(0.01, 2.0)), rel=1e-6)
    assert errors['theta (deg)'] == pytest.approx(90.0)
    assert errors["D' (cm)"] == pytest.approx((math.hypot(0.01, 2.0) - 2.0) * 100.0)


def test_fake_camera_command_prints_its_port_and_answers_visca(tmp_path):
    import serial
    from pattern_locator.visca import protocol as visca
    link = tmp_path / 'cam'
    proc = subprocess.Popen([sys.executable, '-m', 'pattern_locator.cli', 'fake-camera',
                             '--link', str(link), '--init-s', '0.1'],
                            stdout=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        assert line.strip() == f'fake EVI-D31 on {link}', line
        with serial.Serial(str(link), 9600, timeout=1.0) as port:
            port.write(visca.address_set())
            assert port.read(4) == visca.address_set_reply(2)
            port.write(visca.inquiry_power(1))
            assert port.read(4) == visca.answer(1, bytes((visca.POWER_ON,)))
    finally:
        proc.terminate()
        assert proc.wait(timeout=10) == 0


@pytest.mark.parametrize('config, node_module', [('camera_driver.yaml', 'camera_driver_node'),
                                                 ('locator.yaml', 'locator_node'),
                                                 ('sim.yaml', 'sim_node')])
def test_shipped_parameter_files_name_only_declared_parameters(config, node_module):
    import importlib
    import yaml
    path = Path(__file__).resolve().parents[2] / 'config' / config
    data = yaml.safe_load(path.read_text())
    (node_name, section), = data.items()
    names = set(section['ros__parameters'])
    module = importlib.import_module(f'pattern_locator.nodes.{node_module}')
    declared = {p.name for p in module.PARAMETERS}
    assert names == declared, (names ^ declared)
    # And with the declared defaults: the file documents them.
    defaults = {p.name: p.default for p in module.PARAMETERS}
    assert dict(section['ros__parameters']) == defaults
