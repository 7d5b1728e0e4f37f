"""
Launch the camera driver and the locator on a robot (a real ROS 2 Jazzy install).

    ros2 launch pattern_locator robot.launch.py port:=/dev/ttyUSB0 [namespace:=robot2]
        [use_sim_time:=true] [params_file:=my_robot.yaml] [log_level:=debug]

Each node gets its installed file (``config/camera_driver.yaml``,
``config/locator.yaml``), then ``params_file`` when one is given: one file
for both, its ``/**/camera_driver`` and ``/**/locator`` sections override
the installed values. ``port`` is the EVI-D31's serial port. The frame
grabber's driver (publishing ``camera/image_raw`` in the same namespace)
runs beside them. The launch modules are imported inside the functions, so
this file also imports where ``launch`` is not installed.
"""

import os

PACKAGE = 'pattern_locator'

# The declared launch arguments: name, default, description.
ARGUMENTS = (
    ('namespace', '', 'namespace of the nodes and their topics (e.g. robot2; empty: none)'),
    ('use_sim_time', 'false', 'take the time from /clock (a simulation, a bag played with '
     '--clock)'),
    ('params_file', '', 'parameter file applied after the installed config/camera_driver.yaml '
     'and config/locator.yaml (empty: the installed files alone)'),
    ('log_level', 'info', 'log level: debug, info, warn, error or fatal'),
    ('port', '/dev/ttyUSB0', "serial port of the EVI-D31's VISCA line"),
)


def node_parameters(share: str, config: str, params_file: str, use_sim_time: str) -> list:
    """Return a node's parameters: the installed file, the given one, use_sim_time."""
    files = [os.path.join(share, 'config', config)] + ([params_file] if params_file else [])
    return files + [{'use_sim_time': use_sim_time.strip().lower() in ('true', '1', 'yes')}]


def _nodes(context):
    from ament_index_python.packages import get_package_share_directory
    from launch_ros.actions import Node

    def arg(name):
        return context.launch_configurations[name]

    share = get_package_share_directory(PACKAGE)
    common = {'namespace': arg('namespace'), 'output': 'screen',
              'ros_arguments': ['--log-level', arg('log_level')]}
    driver = node_parameters(share, 'camera_driver.yaml', arg('params_file'),
                             arg('use_sim_time'))
    driver.append({'port': arg('port')})
    return [
        Node(package=PACKAGE, executable='camera_driver', name='camera_driver',
             parameters=driver, **common),
        Node(package=PACKAGE, executable='locator', name='locator',
             parameters=node_parameters(share, 'locator.yaml', arg('params_file'),
                                        arg('use_sim_time')), **common),
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
