"""Test-session set-up: localhost-only DDS discovery and a ROS domain per run and worker."""

import os
from pathlib import Path
import random

# Never multicast discovery out of the machine.
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'


def _domain_id() -> int:
    """
    Return this process's ROS domain: the run's, moved on by the xdist worker's number.

    Parallel test runs (and a developer's own ROS graph) are kept apart by the
    run's domain (the Makefile picks one per invocation, else a random one);
    parallel workers of one run by their own offset, so two tests running at
    the same time never see each other's topics.
    """
    base = os.environ.get('ROS_DOMAIN_ID', '')
    base = int(base) if base.isdigit() else random.Random(os.getpid()).randint(101, 190)
    worker = os.environ.get('PYTEST_XDIST_WORKER', '')
    offset = int(worker[2:]) + 1 if worker.startswith('gw') and worker[2:].isdigit() else 0
    # Domains 1..232 are valid for Fast DDS's port mapping.
    return 1 + (base + offset * 37 - 1) % 232


os.environ['ROS_DOMAIN_ID'] = str(_domain_id())
# Camera images are bigger than Fast DDS's default shared-memory segment:
# the project's profile makes room for them (see config/).
os.environ.setdefault('FASTRTPS_DEFAULT_PROFILES_FILE', str(
    Path(__file__).resolve().parent.parent / 'config' / 'fastdds_large_messages.xml'))
