"""AprilTag and ArUco baselines: card bitmaps, corner order and pose accuracy."""

import gc
import math

import cv2
import numpy as np
from pattern_locator.errors import ImageError
from pattern_locator.evaluation.baselines import (AprilTagLocator, ArucoLocator, KINDS,
                                                  make_locator, square_pose, square_pose_solutions,
                                                  tag_black_size, tag_card_bitmap,
                                                  tag_object_points)
from pattern_locator.sim.render import (BitmapCardTexture, card_pose_facing, CardPlacement,
                                        render_scene, RenderOptions)
from pattern_locator.vision.camera import CameraModel
from pattern_locator.vision.geometry import Pose, rotation_angle
import pytest

CARD = 0.3
TAG_ID = 7
CAMERA = CameraModel.from_fov(640, 480, 60.0)
BARREL = CameraModel.from_fov(1280, 720, 70.0, D=[-0.25, 0.07, 0.0, 0.0, 0.0])
OPTIONS = RenderOptions(noise_sigma=2.0, seed=3)


@pytest.fixture(scope='module')
def locators():
    return {'apriltag': AprilTagLocator(CARD), 'aruco': ArucoLocator(CARD)}


def render(kind, pose, camera=CAMERA, options=OPTIONS):
    texture = BitmapCardTexture(tag_card_bitmap(kind, TAG_ID), CARD)
    return render_scene(camera, [CardPlacement(pose, texture)], options).image


def only_detection(locator, image, camera):
    detections = locator.detect(image, camera)
    assert [d.tag_id for d in detections] == [TAG_ID]
    return detections[0]


def assert_pose_close(estimate: Pose, truth: Pose, position_frac=0.02, rotation_deg=2.0):
    distance = float(np.linalg.norm(truth.t))
    assert np.linalg.norm(estimate.t - truth.t) < position_frac * distance
    assert math.degrees(rotation_angle(estimate.R, truth.R)) < rotation_deg


def official_tag36h11(family, tag_id):
    """Draw a tag as the AprilTag C library does (apriltag_to_image)."""
    image = np.full((family.total_width, family.total_width), 255, dtype=np.uint8)
    start = (family.total_width - family.width_at_border) // 2
    image[start:start + family.width_at_border, start:start + family.width_at_border] = 0
    code = family.codes[tag_id]
    for i in range(family.nbits):
        if code & (1 << (family.nbits - 1 - i)):
            image[family.bit_y[i] + start, family.bit_x[i] + start] = 255
    return image


# Bitmaps and geometry ---------------------------------------------------------

@pytest.mark.parametrize('kind', KINDS)
def test_bitmap_layout(kind):
    card = tag_card_bitmap(kind, TAG_ID, cells_per_side_px=4)
    assert card.dtype == np.uint8 and card.shape == (40, 40)
    assert set(np.unique(card)) <= {0, 255}
    # One white cell of margin, then the one-cell black border of the marker.
    ring = np.ones((40, 40), dtype=bool)
    ring[4:36, 4:36] = False
    assert np.all(card[ring] == 255)
    border = np.zeros((40, 40), dtype=bool)
    border[4:36, 4:36] = True
    border[8:32, 8:32] = False
    assert np.all(card[border] == 0)
    assert np.array_equal(card[::4, ::4], tag_card_bitmap(kind, TAG_ID))
    assert tag_black_size(kind, CARD) == pytest.approx(0.8 * CARD)


def test_apriltag_bitmap_is_the_official_tag(locators):
    # OpenCV's tag36h11 dictionary is the official layout turned by 180 deg;
    # the card must be the published tag, i.e. what the C library draws.
    family = locators['apriltag']._detector.tag_families['tag36h11'].contents
    assert family.ncodes == 587
    for tag_id in (0, 1, TAG_ID, 100, 586):
        assert np.array_equal(tag_card_bitmap('apriltag', tag_id),
                              official_tag36h11(family, tag_id))


@pytest.mark.parametrize('kind', KINDS)
def test_upright_bitmap_decodes_upright(kind, locators):
    # A flat, upright, axis-aligned bitmap: the detector must report the id
    # and its corners in the order tag_object_points() assumes.
    scale, pad = 24, 40
    card = np.pad(tag_card_bitmap(kind, TAG_ID, scale), pad, constant_values=255)
    camera = CameraModel.from_focal(card.shape[1], card.shape[0], 1000.0)
    detection = only_detection(locators[kind], card, camera)
    # Black square edges at pixel pad + scale - 0.5 and pad + 9 * scale - 0.5.
    low, high = pad + scale - 0.5, pad + 9 * scale - 0.5
    centre = (low + high) / 2.0
    half = (high - low) / 2.0
    signs = tag_object_points(kind, CARD)[:, :2] / (tag_black_size(kind, CARD) / 2.0)
    expected = centre + half * signs * [1.0, -1.0]   # image y points down
    assert np.abs(detection.corners_px - expected).max() < 0.35


def test_object_points_are_the_black_square_in_detector_order():
    h = 0.4 * CARD
    assert np.allclose(tag_object_points('apriltag', CARD),
                       [[-h, -h, 0], [h, -h, 0], [h, h, 0], [-h, h, 0]])
    assert np.allclose(tag_object_points('aruco', CARD),
                       [[-h, h, 0], [h, h, 0], [h, -h, 0], [-h, -h, 0]])


def test_bad_arguments():
    with pytest.raises(ValueError):
        tag_card_bitmap('qr', 1)
    with pytest.raises(ValueError):
        tag_card_bitmap('apriltag', 587)
    with pytest.raises(ValueError):
        tag_card_bitmap('aruco', 250)
    with pytest.raises(ValueError):
        tag_card_bitmap('aruco', 1, 0)
    with pytest.raises(ValueError):
        ArucoLocator(CARD, noSuchParameter=1)
    with pytest.raises(ValueError):
        AprilTagLocator(0.0)


# Detection and pose ----------------------------------------------------------------

@pytest.mark.parametrize('kind', KINDS)
def test_card_at_2m_30deg(kind, locators):
    truth = card_pose_facing(2.0, 30.0, 60.0, offset_px=(40.0, -25.0), camera=CAMERA)
    detection = only_detection(locators[kind], render(kind, truth), CAMERA)
    assert_pose_close(detection.T_camera_card, truth)
    assert detection.reprojection_rms_px < 1.0
    expected = CAMERA.project(truth.apply(tag_object_points(kind, CARD)))
    assert np.abs(detection.corners_px - expected).max() < 1.0


@pytest.mark.parametrize('kind', KINDS)
@pytest.mark.parametrize('roll', [90.0, -90.0, 180.0])
def test_rotated_card_keeps_corner_order(kind, roll, locators):
    truth = card_pose_facing(1.5, 25.0, 200.0, roll_deg=roll)
    detection = only_detection(locators[kind], render(kind, truth), CAMERA)
    assert_pose_close(detection.T_camera_card, truth)


@pytest.mark.parametrize('kind', KINDS)
def test_barrel_distorted_camera(kind, locators):
    # Off-centre, where the lens bends the card edges most.
    truth = card_pose_facing(2.0, 30.0, 120.0, offset_px=(420.0, 220.0), camera=BARREL)
    image = render(kind, truth, BARREL)
    detection = only_detection(locators[kind], image, BARREL)
    assert_pose_close(detection.T_camera_card, truth)
    # Ignoring the distortion would be visibly wrong: the model must matter.
    pinhole = CameraModel(BARREL.width, BARREL.height, BARREL.K)
    wrong = square_pose(detection.corners_px, kind, CARD, pinhole)[0]
    assert np.linalg.norm(wrong.t - truth.t) > np.linalg.norm(
        detection.T_camera_card.t - truth.t)


@pytest.mark.parametrize('kind', KINDS)
def test_both_flip_solutions(kind, locators):
    # A small, nearly frontal card: the two IPPE solutions are both
    # plausible; the true one must be among them and the best one first.
    truth = card_pose_facing(3.0, 8.0, 45.0)
    detection = only_detection(locators[kind], render(kind, truth), CAMERA)
    solutions = square_pose_solutions(detection.corners_px, kind, CARD, CAMERA)
    assert len(solutions) == 2
    costs = [cost for _, cost in solutions]
    assert costs == sorted(costs)
    assert solutions[0][0].t == pytest.approx(detection.T_camera_card.t)
    assert math.sqrt(costs[0] / 4.0) == pytest.approx(detection.reprojection_rms_px)
    assert min(math.degrees(rotation_angle(pose.R, truth.R)) for pose, _ in solutions) < 4.0
    # The two solutions are mirror images about the line of sight.
    assert math.degrees(rotation_angle(solutions[0][0].R, solutions[1][0].R)) > 5.0


@pytest.mark.parametrize('kind', KINDS)
def test_fisheye_camera(kind, locators):
    wide = CameraModel.from_fov(800, 600, 100.0)
    fisheye = CameraModel(800, 600, wide.K, [0.05, -0.02, 0.003, 0.0], 'equidistant')
    truth = card_pose_facing(1.5, 30.0, 120.0, offset_px=(250.0, 150.0), camera=fisheye)
    detection = only_detection(locators[kind], render(kind, truth, fisheye), fisheye)
    assert_pose_close(detection.T_camera_card, truth)


@pytest.mark.parametrize('kind', KINDS)
def test_empty_images_give_nothing(kind, locators):
    wall = render_scene(CAMERA, [], OPTIONS).image
    clutter = render_scene(CAMERA, [], RenderOptions(background='clutter', seed=5)).image
    black = np.zeros((CAMERA.height, CAMERA.width, 3), dtype=np.uint8)
    for image in (wall, clutter, black):
        assert locators[kind].detect(image, CAMERA) == []


@pytest.mark.parametrize('kind', KINDS)
def test_gray_input_and_bad_images(kind, locators):
    truth = card_pose_facing(1.2, 10.0, 0.0)
    image = render(kind, truth)
    gray = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    detection = only_detection(locators[kind], gray, CAMERA)
    assert_pose_close(detection.T_camera_card, truth)
    with pytest.raises(ImageError):
        locators[kind].detect(image.astype(np.float32), CAMERA)
    with pytest.raises(ImageError):
        locators[kind].detect(np.zeros((4, 4, 2), dtype=np.uint8), CAMERA)


def test_make_locator():
    assert isinstance(make_locator('apriltag'), AprilTagLocator)
    assert isinstance(make_locator('aruco', 0.2), ArucoLocator)
    with pytest.raises(ValueError):
        make_locator('qr')


def test_apriltag_settings_reach_the_c_detector():
    locator = AprilTagLocator(CARD, quad_decimate=1.0)
    c_detector = locator._detector.tag_detector_ptr.contents
    # pupil-apriltags alone would store int(0.25) = 0.
    assert c_detector.decode_sharpening == pytest.approx(0.25)
    assert c_detector.quad_decimate == pytest.approx(1.0)
    assert c_detector.nthreads == 1
    assert c_detector.refine_edges == 1


def test_apriltag_locators_can_be_dropped():
    # pupil-apriltags' own destructor frees the tag family before the
    # detector, whose destructor then writes into it (heap corruption). The
    # locator must free both itself, detector first, and disarm the wrapper.
    image = np.random.default_rng(0).integers(0, 256, (120, 160), dtype=np.uint8)
    camera = CameraModel.from_fov(160, 120, 60.0)
    locator = AprilTagLocator(CARD)
    locator.detect(image, camera)
    inner = locator._detector
    del locator
    gc.collect()
    assert inner.tag_detector_ptr is None and inner.tag_families == {}
    for _ in range(20):
        locator = AprilTagLocator(CARD)
        locator.detect(image, camera)
        del locator
