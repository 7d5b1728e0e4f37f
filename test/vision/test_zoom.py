"""A zoomed, sharpened window (vision.zoom): its camera and its map back agree with the image's."""

import cv2
import numpy as np
from pattern_locator.vision.camera import CameraModel
from pattern_locator.vision.zoom import ZOOM, zoom_window

HD = CameraModel.from_fov(1280, 720, 70.0, D=[-0.25, 0.07, 0.0005, -0.0003, 0.0])


def test_the_window_camera_sees_a_point_where_the_map_back_puts_it():
    rng = np.random.default_rng(3)
    image = np.full((720, 1280, 3), 200, np.uint8)
    for u, v in ((640, 360), (90, 600), (1200, 40)):
        window = zoom_window(image, HD, u, v, 40)
        assert (window.camera.height, window.camera.width) == window.image.shape[:2]
        # Points seen near the window, through the same lens.
        pixels = np.column_stack([rng.uniform(u - 40, u + 40, 50),
                                  rng.uniform(v - 40, v + 40, 50)])
        rays = np.column_stack([HD.normalize(pixels), np.ones(50)]) * 6.0
        seen = window.camera.project(rays)
        back = seen @ window.to_image()[:2, :2].T + window.to_image()[:2, 2]
        assert np.abs(back - HD.project(rays)).max() < 1e-6


def test_a_dot_in_the_window_maps_back_to_where_it_is_in_the_image():
    image = np.full((480, 640, 3), 210, np.uint8)
    cv2.circle(image, (300, 200), 2, (40, 40, 40), -1)
    window = zoom_window(image, None, 303.0, 197.0, 20)
    darkest = window.image.min(axis=2).astype(float)
    weights = np.clip(150.0 - darkest, 0.0, None)
    ys, xs = np.mgrid[:darkest.shape[0], :darkest.shape[1]]
    centre = np.array([(weights * xs).sum(), (weights * ys).sum(), weights.sum()])
    u, v = (window.to_image() @ centre)[:2] / centre[2]
    assert abs(u - 300.0) < 0.3 and abs(v - 200.0) < 0.3
    assert window.image.shape[:2] == (41 * ZOOM, 41 * ZOOM)


def test_a_window_at_the_edge_is_clipped_and_one_too_small_is_none():
    image = np.full((100, 120), 200, np.uint8)
    window = zoom_window(image, None, 2.0, 3.0, 20)
    assert (window.x0, window.y0) == (0, 0) and window.image.shape == (24 * ZOOM, 23 * ZOOM)
    assert zoom_window(image, None, 118.0, 50.0, 2) is None
