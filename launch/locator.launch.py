"""Launch the locator node with the shipped parameters (a real ROS 2 Jazzy install)."""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import SetEnvironmentVariable
from launch_ros.actions import Node


def generate_launch_description():
    share = get_package_share_directory('pattern_locator')
    return LaunchDescription([
        # Room for camera images in Fast DDS's shared memory.
        SetEnvironmentVariable('FASTRTPS_DEFAULT_PROFILES_FILE',
                               os.path.join(share, 'config', 'fastdds_large_messages.xml')),
        Node(package='pattern_locator', executable='locator', name='locator', output='screen',
             parameters=[os.path.join(share, 'config', 'locator.yaml')]),
    ])
