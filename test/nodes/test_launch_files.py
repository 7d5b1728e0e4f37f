"""
The launch files: their declared arguments and what they give the nodes.

``launch`` and ``launch_ros`` are not installable here (they come with a ROS
2 install): the launch files import them inside their functions, so this
test imports the files and reads their argument tables and helpers. Only
building the LaunchDescription itself needs ``launch_ros``: that test skips
when it is missing, and says so.
"""

import importlib.util
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[2]
LAUNCH = ROOT / 'launch'
COMMON = ['namespace', 'use_sim_time', 'params_file', 'log_level']
EXPECTED = {'locator.launch.py': COMMON, 'robot.launch.py': COMMON + ['port'],
            'sim.launch.py': COMMON + ['port', 'world', 'mount_pitch_deg']}


def load(name: str):
    spec = importlib.util.spec_from_file_location(name.replace('.', '_'), LAUNCH / name)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize('name', sorted(EXPECTED))
def test_declared_arguments(name):
    module = load(name)
    arguments = {n: (default, description) for n, default, description in module.ARGUMENTS}
    assert list(arguments) == EXPECTED[name]
    assert arguments['use_sim_time'][0] == 'false'
    assert arguments['namespace'][0] == ''
    assert arguments['log_level'][0] == 'info'
    # Empty: the installed configuration alone.
    assert arguments['params_file'][0] == '' and 'installed' in arguments['params_file'][1]
    assert all(description for _, description in arguments.values())


@pytest.mark.parametrize('name', sorted(EXPECTED))
def test_nodes_get_the_installed_file_then_the_given_one(name):
    module = load(name)
    share = '/opt/ros/jazzy/share/pattern_locator'
    assert module.node_parameters(share, 'locator.yaml', '', 'false') == [
        f'{share}/config/locator.yaml', {'use_sim_time': False}]
    assert module.node_parameters(share, 'locator.yaml', '/my.yaml', 'True') == [
        f'{share}/config/locator.yaml', '/my.yaml', {'use_sim_time': True}]


def test_two_simulated_robots_get_two_camera_ports():
    module = load('sim.launch.py')
    first, second = module.camera_port('', 'robot1'), module.camera_port('', '/robot2')
    assert first != second and first.endswith('evi_d31') and 'robot2' in second
    assert module.camera_port('/dev/pts/7', 'robot1') == '/dev/pts/7'


def test_the_sim_world_tells_every_node_the_same():
    """world:=floor gives the locator the floor's map; the mount pitch reaches all three."""
    module = load('sim.launch.py')
    share = '/opt/ros/jazzy/share/pattern_locator'
    floor = module.world_defaults(share, 'floor', '15.0')
    assert floor['sim'] == {'world': 'floor', 'head_mount_pitch_deg': 15.0}
    assert floor['camera_driver'] == {'head_mount_pitch_deg': 15.0}
    assert floor['locator']['building_map'] == f'{share}/config/floor_building.yaml'
    assert floor['locator']['gates.footprint'] == 'building'
    assert floor['locator']['head.mount_pitch_deg'] == 15.0
    paper = module.world_defaults(share, 'paper', '0')
    assert 'building_map' not in paper['locator'] and paper['sim']['world'] == 'paper'
    with pytest.raises(ValueError, match='floor or paper'):
        module.world_defaults(share, 'moon', '0')
    # The installed file, then the world's values, then the user's file (it wins).
    assert module.node_parameters(share, 'sim.yaml', '/my.yaml', 'true', floor['sim']) == [
        f'{share}/config/sim.yaml', floor['sim'], '/my.yaml', {'use_sim_time': True}]


def test_installed_files_apply_in_any_namespace():
    """A parameter file's 'locator:' section would not reach /robot2/locator: '/**/locator'."""
    for config, node in (('locator.yaml', 'locator'), ('camera_driver.yaml', 'camera_driver'),
                         ('sim.yaml', 'sim')):
        data = yaml.safe_load((ROOT / 'config' / config).read_text())
        assert list(data) == [f'/**/{node}'], config


def test_setup_installs_every_launch_file():
    text = (ROOT / 'setup.py').read_text()
    assert "glob('launch/*.launch.py')" in text
    assert sorted(p.name for p in LAUNCH.glob('*.launch.py')) == sorted(EXPECTED)


@pytest.mark.parametrize('name', sorted(EXPECTED))
def test_launch_description_declares_the_arguments(name):
    pytest.importorskip('launch_ros', reason='launch_ros is not installable here (it comes '
                        'with a ROS 2 install): the LaunchDescription itself is not built')
    from launch.actions import DeclareLaunchArgument
    description = load(name).generate_launch_description()
    declared = [e.name for e in description.entities if isinstance(e, DeclareLaunchArgument)]
    assert declared == EXPECTED[name]
