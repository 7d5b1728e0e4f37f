"""The simulated floor, loaded once for the sim tests."""

from dataclasses import replace

from pattern_locator.sim.floor_file import load_floor_world
from pattern_locator.sim.floor_scene import FloorScene
from pattern_locator.sim.world import SIM_RENDER_OPTIONS
import pytest


@pytest.fixture(scope='session')
def floor_world():
    return load_floor_world()


@pytest.fixture(scope='session')
def quiet_scene(floor_world):
    """Return the floor rendered without sensor noise, for measurements on the images."""
    return FloorScene(floor_world, options=replace(SIM_RENDER_OPTIONS, noise_sigma=0.0))
