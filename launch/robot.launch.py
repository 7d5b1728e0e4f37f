"""Launch the camera driver and the locator on a robot (a real ROS 2 Jazzy install)."""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, SetEnvironmentVariable
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description():
    share = get_package_share_directory('pattern_locator')
    config = os.path.join(share, 'config')
    return LaunchDescription([
        DeclareLaunchArgument('port', default_value='/dev/ttyUSB0',
                              description="serial port of the EVI-D31's VISCA line"),
        # Room for camera images in Fast DDS's shared memory.
        SetEnvironmentVariable('FASTRTPS_DEFAULT_PROFILES_FILE',
                               os.path.join(config, 'fastdds_large_messages.xml')),
        Node(package='pattern_locator', executable='camera_driver', name='camera_driver',
             output='screen', parameters=[os.path.join(config, 'camera_driver.yaml'),
                                          {'port': LaunchConfiguration('port')}]),
        Node(package='pattern_locator', executable='locator', name='locator', output='screen',
             parameters=[os.path.join(config, 'locator.yaml')]),
    ])
