"""
Launch the whole simulated robot: sim, camera driver and locator (a real ROS 2 Jazzy install).

    ros2 launch pattern_locator sim.launch.py [namespace:=robot2] [use_sim_time:=true]
        [params_file:=my_sim.yaml] [log_level:=debug] [port:=/tmp/robot2/evi_d31]

The sim renders the camera images and runs an emulated EVI-D31 on a
pseudo-terminal reached through ``port`` (a symlink it creates; empty: a
path of the namespace's own under the temporary directory, so that two
robots side by side do not share one); the driver opens that port; the
locator locates the robot. Each node gets its installed file
(``config/sim.yaml``, ``config/camera_driver.yaml``, ``config/locator.yaml``),
then ``params_file`` when one is given (one file for all three, by their
``/**/sim``, ``/**/camera_driver`` and ``/**/locator`` sections). The
launch modules are imported inside the functions, so this file also imports
where ``launch`` is not installed.
"""

import os
import tempfile

PACKAGE = 'pattern_locator'

# The declared launch arguments: name, default, description.
ARGUMENTS = (
    ('namespace', '', 'namespace of the nodes and their topics (e.g. robot2; empty: none)'),
    ('use_sim_time', 'false', 'take the time from /clock (none of these nodes publishes it)'),
    ('params_file', '', 'parameter file applied after the installed config/sim.yaml, '
     'config/camera_driver.yaml and config/locator.yaml (empty: the installed files alone)'),
    ('log_level', 'info', 'log level: debug, info, warn, error or fatal'),
    ('port', '', "path of the emulated camera's port (empty: one per namespace under the "
     'temporary directory)'),
)


def node_parameters(share: str, config: str, params_file: str, use_sim_time: str) -> list:
    """Return a node's parameters: the installed file, the given one, use_sim_time."""
    files = [os.path.join(share, 'config', config)] + ([params_file] if params_file else [])
    return files + [{'use_sim_time': use_sim_time.strip().lower() in ('true', '1', 'yes')}]


def camera_port(port: str, namespace: str) -> str:
    """Return the emulated camera's port: the given one, else one of the namespace's own."""
    if port:
        return port
    name = namespace.strip('/').replace('/', '_') or 'root'
    return os.path.join(tempfile.gettempdir(), f'pattern_locator_sim_{name}', 'evi_d31')


def _nodes(context):
    from ament_index_python.packages import get_package_share_directory
    from launch_ros.actions import Node

    def arg(name):
        return context.launch_configurations[name]

    share = get_package_share_directory(PACKAGE)
    port = camera_port(arg('port'), arg('namespace'))
    common = {'namespace': arg('namespace'), 'output': 'screen',
              'ros_arguments': ['--log-level', arg('log_level')]}

    def parameters(config, extra):
        return node_parameters(share, config, arg('params_file'), arg('use_sim_time')) + [extra]

    return [
        Node(package=PACKAGE, executable='sim', name='sim',
             parameters=parameters('sim.yaml', {'camera_link': port}), **common),
        Node(package=PACKAGE, executable='camera_driver', name='camera_driver',
             parameters=parameters('camera_driver.yaml', {'port': port}), **common),
        Node(package=PACKAGE, executable='locator', name='locator',
             parameters=parameters('locator.yaml', {}), **common),
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
