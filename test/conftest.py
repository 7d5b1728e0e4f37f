"""Test-session set-up: localhost-only DDS discovery and a ROS domain per run."""

import os
from pathlib import Path
import random

# Never multicast discovery out of the machine, and keep parallel test runs
# (and a developer's own ROS graph) apart.
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('ROS_DOMAIN_ID', str(random.Random(os.getpid()).randint(101, 200)))
# Camera images are bigger than Fast DDS's default shared-memory segment:
# the project's profile makes room for them (see config/).
os.environ.setdefault('FASTRTPS_DEFAULT_PROFILES_FILE', str(
    Path(__file__).resolve().parent.parent / 'config' / 'fastdds_large_messages.xml'))
