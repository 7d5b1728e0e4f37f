"""Rendered views of the shipped building for the localizer and node tests."""

import numpy as np
from pattern_locator.card.pattern import load_pattern_config
from pattern_locator.localization.building import load_building
from pattern_locator.localization.head import HeadGeometry
from pattern_locator.sim.render import CardPlacement, DotCardTexture, render_scene, RenderOptions
from pattern_locator.vision.camera import CameraModel
from pattern_locator.vision.geometry import Pose, rodrigues

PATTERN = load_pattern_config()
BUILDING = load_building(None, PATTERN)
HEAD = HeadGeometry()
CAMERA = CameraModel.from_fov(640, 480, 60.0)


def base_pose(x: float, y: float, yaw_deg: float) -> Pose:
    """Return ``T_room_base`` of a robot standing on the floor at (x, y) with a heading."""
    return Pose(rodrigues(np.array([0.0, 0.0, np.radians(yaw_deg)])), np.array([x, y, 0.0]))


def view(floor: int, room: int, T_room_base: Pose, pan: float, tilt: float, seed: int = 1,
         camera: CameraModel = CAMERA, pattern=PATTERN):
    """Render what the head's camera sees of the room's cards; return (image, T_room_camera)."""
    T_room_camera = T_room_base @ HEAD.T_base_camera(pan, tilt)
    cards = []
    for card in BUILDING.room(floor, room).cards:
        T_camera_card = T_room_camera.inverse() @ card.T_room_card
        if T_camera_card.t[2] <= 0.3:
            continue
        cards.append(CardPlacement(T_camera_card, DotCardTexture(pattern, card.code),
                                   code=card.code, config=pattern))
    options = RenderOptions(noise_sigma=1.5, defocus_sigma_px=0.5, seed=seed)
    return render_scene(camera, cards, options).image, T_room_camera
