"""
Launch the whole simulated robot: sim, camera driver and locator (a real ROS 2 Jazzy install).

    ros2 launch pattern_locator sim.launch.py [world:=paper] [namespace:=robot2]
        [use_sim_time:=true] [params_file:=my_sim.yaml] [log_level:=debug]
        [port:=/tmp/robot2/evi_d31] [mount_pitch_deg:=15.0]

The sim drives the robot through ``world`` (``floor``: a route of the floor
world ``config/sim_floor.yaml``, the locator given its building map
``config/floor_building.yaml`` and the building as the base's footprint,
since cards of a room are seen from the corridor through its door;
``paper``: the paper's one room of ``config/building.yaml``), renders the
camera images, publishes odometry and runs an emulated EVI-D31 on a
pseudo-terminal reached through ``port`` (a symlink it creates; empty: a
path of the namespace's own under the temporary directory, so that two
robots side by side do not share one); the driver opens that port; the
locator locates the robot. ``mount_pitch_deg`` is the simulated camera's
pitch on its tilt link, told to all three nodes. With ``use_sim_time`` the
sim publishes its time on ``/clock`` (``publish_clock``) and the three
nodes take their time from it.

Each node gets its installed file (``config/sim.yaml``,
``config/camera_driver.yaml``, ``config/locator.yaml``), then what ``world``
and ``mount_pitch_deg`` imply, then ``params_file`` when one is given (one
file for all three, by their ``/**/sim``, ``/**/camera_driver`` and
``/**/locator`` sections: it wins over the arguments), then ``use_sim_time``
and the port. The launch modules are imported inside the functions, so this
file also imports where ``launch`` is not installed.
"""

import os
import tempfile
from typing import Dict, Optional

PACKAGE = 'pattern_locator'

# The declared launch arguments: name, default, description.
ARGUMENTS = (
    ('namespace', '', 'namespace of the nodes and their topics (e.g. robot2; empty: none)'),
    ('use_sim_time', 'false', 'take the time from /clock, which the sim then publishes'),
    ('params_file', '', 'parameter file applied after the installed config/sim.yaml, '
     'config/camera_driver.yaml and config/locator.yaml (empty: the installed files alone)'),
    ('log_level', 'info', 'log level: debug, info, warn, error or fatal'),
    ('port', '', "path of the emulated camera's port (empty: one per namespace under the "
     'temporary directory)'),
    ('world', 'floor', "floor (the floor world and its building map) or paper (the paper's "
     'one room)'),
    ('mount_pitch_deg', '15.0', "the simulated camera's pitch on its tilt link (deg), told to "
     'the sim, the driver and the locator'),
)


def truthy(text: str) -> bool:
    """Return a launch argument's boolean value."""
    return text.strip().lower() in ('true', '1', 'yes')


def node_parameters(share: str, config: str, params_file: str, use_sim_time: str,
                    defaults: Optional[Dict] = None) -> list:
    """Return a node's parameters: the installed file, ``defaults``, the given file, sim time."""
    files = [os.path.join(share, 'config', config)] + ([defaults] if defaults else []) + (
        [params_file] if params_file else [])
    return files + [{'use_sim_time': truthy(use_sim_time)}]


def camera_port(port: str, namespace: str) -> str:
    """Return the emulated camera's port: the given one, else one of the namespace's own."""
    if port:
        return port
    name = namespace.strip('/').replace('/', '_') or 'root'
    return os.path.join(tempfile.gettempdir(), f'pattern_locator_sim_{name}', 'evi_d31')


def world_defaults(share: str, world: str, mount_pitch_deg: str) -> Dict[str, Dict]:
    """Return, per node, the parameters that ``world`` and ``mount_pitch_deg`` imply."""
    world = world.strip().lower()
    if world not in ('floor', 'paper'):
        raise ValueError(f"world must be floor or paper, got '{world}'")
    pitch = float(mount_pitch_deg)
    locator = {'head.mount_pitch_deg': pitch}
    if world == 'floor':
        locator.update({'building_map': os.path.join(share, 'config', 'floor_building.yaml'),
                        'gates.footprint': 'building'})
    return {'sim': {'world': world, 'head_mount_pitch_deg': pitch},
            'camera_driver': {'head_mount_pitch_deg': pitch},
            'locator': locator}


def _nodes(context):
    from ament_index_python.packages import get_package_share_directory
    from launch_ros.actions import Node

    def arg(name):
        return context.launch_configurations[name]

    share = get_package_share_directory(PACKAGE)
    port = camera_port(arg('port'), arg('namespace'))
    defaults = world_defaults(share, arg('world'), arg('mount_pitch_deg'))
    common = {'namespace': arg('namespace'), 'output': 'screen',
              'ros_arguments': ['--log-level', arg('log_level')]}

    def parameters(node, extra):
        return node_parameters(share, f'{node}.yaml', arg('params_file'), arg('use_sim_time'),
                               defaults[node]) + [extra]

    return [
        Node(package=PACKAGE, executable='sim', name='sim',
             parameters=parameters('sim', {'camera_link': port,
                                           'publish_clock': truthy(arg('use_sim_time'))}),
             **common),
        Node(package=PACKAGE, executable='camera_driver', name='camera_driver',
             parameters=parameters('camera_driver', {'port': port}), **common),
        Node(package=PACKAGE, executable='locator', name='locator',
             parameters=parameters('locator', {}), **common),
    ]


def generate_launch_description():
    from ament_index_python.packages import get_package_share_directory
    from launch import LaunchDescription
    from launch.actions import DeclareLaunchArgument, OpaqueFunction, SetEnvironmentVariable

    share = get_package_share_directory(PACKAGE)
    return LaunchDescription(
        [DeclareLaunchArgument(name, default_value=default, description=description)
         for name, default, description in ARGUMENTS] + [
            # Room for camera images in Fast DDS's shared memory.
            SetEnvironmentVariable('FASTRTPS_DEFAULT_PROFILES_FILE',
                                   os.path.join(share, 'config', 'fastdds_large_messages.xml')),
            OpaqueFunction(function=_nodes)])
