"""Test-session set-up: localhost-only DDS discovery and a ROS domain per run."""

import os
import random

# Never multicast discovery out of the machine, and keep parallel test runs
# (and a developer's own ROS graph) apart.
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('ROS_DOMAIN_ID', str(random.Random(os.getpid()).randint(101, 200)))
