"""
The camera_driver's shutter (issue 12): the parameter; the driver process on the emulated camera.

The driver runs as a real process (``python -m pattern_locator.nodes.camera_driver_node``)
on the emulated EVI-D31's pseudo-terminal, over DDS in the test session's ROS domain.
"""

import subprocess

from diagnostic_msgs.msg import DiagnosticArray
from pattern_locator.nodes.camera_driver_node import CameraDriverNode, PARAMETERS, shutter_request
from pattern_locator.nodes.node_process import node_command, node_process
from pattern_locator.visca import protocol as visca
from pattern_locator.visca.emulator import EmulatedEviD31
import pytest
from ros_tools import client_node, spin_until
from sensor_msgs.msg import JointState

DEFAULTS = {p.name: p.default for p in PARAMETERS}
SPECS = {p.name: p for p in PARAMETERS}
APPLIED = 'shutter 1/250 s (shutter priority)'


def test_shutter_parameters_are_checked():
    assert shutter_request(DEFAULTS) is None                     # 0: the camera's own
    request = shutter_request({**DEFAULTS, 'shutter_s': 0.0042})
    assert (request.position, request.describe()) == (0x09, '1/250 s')
    assert shutter_request({**DEFAULTS, 'shutter_s': 0.02, 'video_standard': 'ntsc'}
                           ).describe() == '1/60 s'
    assert CameraDriverNode._validate({**DEFAULTS, 'shutter_s': 0.004}) is None
    problem = CameraDriverNode._validate({**DEFAULTS, 'shutter_s': 2e-5})
    assert problem.startswith('shutter_s: shutter time 2e-05 s is outside what the camera can '
                              'do (1/10000 .. 1/50 s, PAL)'), problem
    assert '0 leaves the auto exposure' in problem
    shutter = SPECS['shutter_s'].descriptor()
    assert shutter.read_only
    assert (shutter.floating_point_range[0].from_value,
            shutter.floating_point_range[0].to_value) == (0.0, 0.04)
    standard = SPECS['video_standard']
    assert standard.descriptor().read_only and standard.check('ntsc') is None
    assert standard.check('secam') == \
        "video_standard must be one of pal, ntsc, got 'secam'"


@pytest.fixture
def ros_node():
    with client_node('shutter_test') as pair:
        yield pair


def test_driver_sets_the_shutter_again_after_a_power_cycle_and_survives_a_refusal(
        tmp_path, ros_node):
    node, executor = ros_node
    joints, diagnostics = [], []
    node.create_subscription(JointState, 'camera/joint_states', joints.append, 10)
    node.create_subscription(DiagnosticArray, '/diagnostics', diagnostics.append, 10)
    # A shutter the camera cannot do: one line at start, exit 1 (runs meanwhile).
    bad = subprocess.Popen(node_command('camera_driver_node', ['shutter_s:=0.00001']),
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    link = tmp_path / 'evi_d31'
    try:
        with EmulatedEviD31(init_s=0.3, link_path=str(link), auto_shutter_s=0.02) as camera, \
                node_process('camera_driver_node', tmp_path / 'driver.log',
                             [f'port:={link}', 'search:=false', 'shutter_s:=0.004']) as driver:
            log = driver.log

            def exposure():
                """Return the diagnostics' exposure value, once there is one."""
                for array in reversed(diagnostics):
                    for status in array.status:
                        values = {kv.key: kv.value for kv in status.values}
                        if status.name == 'camera_driver: EVI-D31' and 'exposure' in values:
                            return values['exposure']
                return None

            def flowing():
                count = len(joints)
                return spin_until(executor, lambda: len(joints) >= count + 5, 20.0)

            assert spin_until(executor, lambda: len(joints) >= 5, 30.0), log.read_text()
            assert camera.state().shutter_s == 1 / 250
            assert spin_until(executor, lambda: log.read_text().count(APPLIED) == 1, 10.0), \
                log.read_text()
            diagnostics.clear()
            assert spin_until(executor, lambda: exposure() == APPLIED, 5.0), exposure()

            # Power cycle: the camera comes up in full auto; the driver sets it again.
            camera.power_cycle()
            assert camera.state().shutter_s == 0.02
            assert spin_until(executor, lambda: camera.state().shutter_s == 1 / 250, 10.0)
            assert spin_until(executor, lambda: log.read_text().count(APPLIED) == 2, 10.0), \
                log.read_text()
            assert flowing()

            # A camera that refuses it (a model without CAM_AE): a warning, tracking goes on.
            camera.faults.refuse_exposure = visca.ERROR_SYNTAX
            camera.power_cycle()
            refused = 'the camera refused the shutter 1/250 s (syntax error'
            assert spin_until(executor, lambda: refused in log.read_text(), 10.0), \
                log.read_text()
            assert camera.state().shutter_s == 0.02
            assert flowing()
            diagnostics.clear()
            assert spin_until(executor, lambda: (exposure() or '').startswith(refused), 5.0)
            assert driver.poll() is None
        text = log.read_text()
        assert 'Traceback' not in text, text
        assert [line for line in text.splitlines() if refused in line][0].startswith('[WARN]')
        out, err = bad.communicate(timeout=60)
        assert bad.returncode == 1, (out, err)
        assert err.strip().splitlines() == [
            'camera_driver: error: shutter_s: shutter time 1e-05 s is outside what the camera '
            'can do (1/10000 .. 1/50 s, PAL); 0 leaves the auto exposure'], err
    finally:
        if bad.poll() is None:
            bad.kill()
            bad.wait()
