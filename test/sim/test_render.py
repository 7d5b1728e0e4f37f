"""Scene renderer: image content agrees with the ground truth it reports."""

import math

import numpy as np
from pattern_locator.card.pattern import Code, PatternConfig
from pattern_locator.errors import CodeError, ConfigError, ImageError
from pattern_locator.sim.render import (BitmapCardTexture, card_pose_facing, CardPlacement,
                                        DotCardTexture, GlossyTexture, ink_reflectance,
                                        MirroredTexture, Occluder, render_scene, RenderOptions)
from pattern_locator.vision.camera import CameraModel
from pattern_locator.vision.geometry import Pose
import pytest

# The paper's card (no handedness marks); the marks have their own tests.
CFG = PatternConfig(handedness_mark=None)
MARKED = PatternConfig()
CODE = Code.parse('R-KRGBBGRG')
CAMERA = CameraModel.from_focal(320, 240, 300.0)
# Frontal and upright: card x = camera x, card y = camera -y.
FRONTAL = np.diag([1.0, -1.0, -1.0])
PLAIN = RenderOptions(background='black')


def linear(image, gamma=2.2):
    """Linear light of an 8-bit BGR image."""
    return (image.astype(np.float64) / 255.0) ** gamma


def encoded(value, gamma=2.2):
    return 255.0 * np.asarray(value) ** (1.0 / gamma)


def dot_card(pose, code=CODE):
    return CardPlacement(pose, DotCardTexture(CFG, code), code, CFG)


def frontal_pose(distance=0.6, shift=(0.0123, -0.0071)):
    return Pose(FRONTAL, np.array([shift[0], shift[1], distance]))


def pixel_index(uv):
    u, v = np.round(uv).astype(int)
    return v, u


def pixel(image, uv):
    return image[pixel_index(uv)].astype(float)


@pytest.fixture(scope='module')
def frontal():
    return render_scene(CAMERA, [dot_card(frontal_pose())], PLAIN)


def test_dot_centroids_match_the_truth(frontal):
    # A card parallel to the image plane images circles as circles centred on
    # the projected centres, so the darkness centroid must hit the truth.
    truth = frontal.truth[0]
    light = linear(frontal.image)
    paper = light[pixel_index(truth.corner_pixels[0] + [8, 8])]
    radii_px = CFG.dot_radii() * CAMERA.fx / 0.6
    v, u = np.mgrid[0:CAMERA.height, 0:CAMERA.width]
    for centre, radius in zip(truth.dot_pixels, radii_px):
        near = np.hypot(u - centre[0], v - centre[1]) < radius + 2.5
        weight = np.clip(paper - light[near], 0.0, None).sum(axis=1)
        centroid = np.array([np.sum(weight * u[near]), np.sum(weight * v[near])]) / weight.sum()
        assert np.linalg.norm(centroid - centre) < 0.1


def test_dots_are_dark_in_their_colours_on_white_paper(frontal):
    truth = frontal.truth[0]
    assert np.all(truth.dot_visible == 1.0)
    white = encoded(0.85)
    dominant = {'R': 2, 'G': 1, 'B': 0}
    for centre, letter in zip(truth.dot_pixels, CFG.dot_colours(CODE)):
        bgr = pixel(frontal.image, centre)
        if letter == 'K':
            assert np.all(bgr < 70)
        else:
            main = dominant[letter]
            others = [c for c in range(3) if c != main]
            assert bgr[main] > bgr[others].max() + 60
            assert bgr[others].max() < 100
    # Paper half-way between neighbouring ring dots, on both rings.
    for ring_radius in CFG.ring_radii:
        for k in range(8):
            angle = math.radians(22.5 + 45.0 * k)
            point = np.array([[ring_radius * math.sin(angle), ring_radius * math.cos(angle), 0]])
            uv = CAMERA.project(truth.T_camera_card.apply(point))[0]
            assert np.all(np.abs(pixel(frontal.image, uv) - white) <= 1.0)


def test_corners_and_background(frontal):
    truth = frontal.truth[0]
    corners = truth.corner_pixels
    # (-s/2, +s/2) first: top left in the image, then clockwise.
    assert corners[0, 0] < corners[1, 0] and corners[0, 1] < corners[3, 1]
    assert np.allclose(corners[2] - corners[0], [150.0, 150.0])
    outside = corners[0] - [10, 10]
    assert np.all(pixel(frontal.image, outside) == np.round(encoded(0.01)))


def test_colour_cast_and_gain_change_the_white():
    cast = (1.0, 0.8, 0.6)
    result = render_scene(CAMERA, [dot_card(frontal_pose())],
                          RenderOptions(background='black', colour_cast=cast, gain=0.9))
    paper_uv = result.truth[0].corner_pixels[0] + [8, 8]
    b, g, r = pixel(result.image, paper_uv)
    expected = encoded(0.85 * 0.9 * np.array(cast))
    assert np.allclose([r, g, b], expected, atol=1.0)
    assert r > g > b


def test_gradient_brightens_one_side():
    result = render_scene(CAMERA, [], RenderOptions(background='white', gradient=0.3,
                                                    gradient_angle_deg=0.0))
    left, right = result.image[120, 0, 1], result.image[120, -1, 1]
    assert right == pytest.approx(encoded(0.85 * 1.3).clip(max=255), abs=1)
    assert left == pytest.approx(encoded(0.85 * 0.7), abs=1)
    down = render_scene(CAMERA, [], RenderOptions(background='white', gradient=0.3,
                                                  gradient_angle_deg=90.0)).image
    assert down[-1, 160, 1] > down[0, 160, 1] + 20


def test_strong_barrel_distortion_moves_dots_where_the_truth_says():
    camera = CameraModel.from_focal(320, 240, 220.0, D=[-0.3, 0.09, 0.0, 0.0, 0.0])
    pose = card_pose_facing(0.6, 10.0, 30.0, offset_px=(80.0, 50.0), camera=camera)
    result = render_scene(camera, [dot_card(pose)], PLAIN)
    truth = result.truth[0]
    points = pose.apply(CFG.model_points())
    assert np.allclose(truth.dot_pixels, camera.project(points))
    ideal = points[:, :2] / points[:, 2:] * camera.fx + [camera.cx, camera.cy]
    assert np.max(np.linalg.norm(ideal - truth.dot_pixels, axis=1)) > 4.0
    light = linear(result.image)
    halfway = (truth.dot_pixels[0] + truth.dot_pixels[1]) / 2.0
    paper = light[pixel_index(halfway)]
    v, u = np.mgrid[0:camera.height, 0:camera.width]
    for centre in truth.dot_pixels:
        near = np.hypot(u - centre[0], v - centre[1]) < 7.5
        weight = np.clip(paper - light[near], 0.0, None).sum(axis=1)
        centroid = np.array([np.sum(weight * u[near]), np.sum(weight * v[near])]) / weight.sum()
        assert np.linalg.norm(centroid - centre) < 0.25
    assert np.all(truth.dot_visible == 1.0)


def covered_fraction(centre_x, radius, edge_x):
    """Fraction of a disc left of the line x = edge_x."""
    a = np.clip((centre_x - edge_x) / radius, -1.0, 1.0)
    return (math.acos(a) - a * math.sqrt(1.0 - a * a)) / math.pi


def test_occluder_hides_dots_exactly():
    edge = -0.09
    polygon = np.array([[-0.2, -0.2], [edge, -0.2], [edge, 0.2], [-0.2, 0.2]])
    colour = (0.35, 0.3, 0.28)
    options = RenderOptions(background='black', occluders=(Occluder(0, polygon, colour),))
    result = render_scene(CAMERA, [dot_card(frontal_pose())], options)
    truth = result.truth[0]
    points, radii = CFG.model_points(), CFG.dot_radii()
    expected = [1.0 - covered_fraction(x, r, edge) for x, r in zip(points[:, 0], radii)]
    assert np.allclose(truth.dot_visible, expected, atol=0.01)
    outer_7 = CFG.dot_index(0, 7)
    assert truth.dot_visible[outer_7] == 0.0
    assert 0.0 < truth.dot_visible[CFG.dot_index(0, 6)] < 1.0
    painted = np.round(encoded(colour))[::-1]
    assert np.allclose(pixel(result.image, truth.dot_pixels[outer_7]), painted, atol=1)
    # The occluder reaches beyond the card, over the background.
    beyond = CAMERA.project(truth.T_camera_card.apply(np.array([[-0.18, 0.0, 0.0]])))[0]
    assert np.allclose(pixel(result.image, beyond), painted, atol=1)


def test_dots_cut_by_the_image_border_are_partly_visible():
    # Card centre on the left image border (u = -0.5).
    pose = card_pose_facing(0.6, 0.0, 0.0, offset_px=(-0.5 - CAMERA.cx, 0.0), camera=CAMERA)
    result = render_scene(CAMERA, [dot_card(pose)], PLAIN)
    visible = result.truth[0].dot_visible
    assert visible[0] == pytest.approx(0.5, abs=0.02)
    assert visible[CFG.dot_index(0, 3)] == 1.0
    assert visible[CFG.dot_index(0, 7)] == 0.0


def test_card_behind_the_camera_draws_nothing():
    empty = render_scene(CAMERA, [], RenderOptions(seed=4))
    for R in (FRONTAL, np.eye(3)):
        result = render_scene(CAMERA, [dot_card(Pose(R, np.array([0.0, 0.0, -0.5])))],
                              RenderOptions(seed=4))
        assert np.array_equal(result.image, empty.image)
        assert np.all(result.truth[0].dot_visible == 0.0)
        assert np.all(np.isnan(result.truth[0].dot_pixels))


def test_surface_through_the_camera_plane_renders_only_in_front():
    # A 2 m floor card 0.3 m below the camera, reaching behind it.
    floor = Pose(np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]),
                 np.array([0.0, 0.3, 0.2]))
    black = BitmapCardTexture(np.zeros((4, 4), dtype=np.uint8), 2.0)
    result = render_scene(CAMERA, [CardPlacement(floor, black)],
                          RenderOptions(background='white'))
    white = np.round(encoded(0.85))
    # Rays above the horizon miss the floor; the bottom rows see it (x <= 1 m).
    assert np.all(result.image[:121] == white)
    assert np.all(result.image[-1, 40:-40] < 60)


def test_nearer_card_hides_the_farther_one_in_any_order():
    far = dot_card(frontal_pose(1.0, (0.0, 0.0)))
    black = BitmapCardTexture(np.zeros((2, 2), dtype=np.uint8), 0.04)
    near = CardPlacement(Pose(FRONTAL, np.array([0.0, 0.0, 0.5])), black)
    first = render_scene(CAMERA, [far, near], PLAIN)
    second = render_scene(CAMERA, [near, far], PLAIN)
    assert np.array_equal(first.image, second.image)
    visible = first.truth[0].dot_visible
    # The near card covers +-0.04 m at the far card's distance: the centre
    # dot only.
    assert visible[0] == 0.0
    assert np.all(visible[1:] == 1.0)
    centre = pixel(first.image, first.truth[0].dot_pixels[0])
    assert np.allclose(centre, np.round(encoded(0.03)), atol=1)
    assert first.truth[1].dot_pixels is None and first.truth[1].dot_visible is None


def test_bitmap_row_zero_is_the_top_of_the_card():
    bitmap = np.full((8, 8, 3), 255, dtype=np.uint8)
    bitmap[:4, :4] = 0  # top-left quadrant black
    card = CardPlacement(frontal_pose(0.6, (0.0, 0.0)), BitmapCardTexture(bitmap, 0.2))
    image = render_scene(CAMERA, [card], PLAIN).image
    centre = np.array([CAMERA.cx, CAMERA.cy])
    quarter = 0.05 * CAMERA.fx / 0.6
    assert np.all(pixel(image, centre + [-quarter, -quarter]) < 60)
    for offset in ([quarter, -quarter], [-quarter, quarter], [quarter, quarter]):
        assert np.all(pixel(image, centre + offset) > 200)


def test_back_of_a_card_is_blank():
    back = Pose(np.diag([-1.0, -1.0, 1.0]), np.array([0.0, 0.0, 0.6]))
    result = render_scene(CAMERA, [dot_card(back)], PLAIN)
    assert np.all(result.truth[0].dot_visible == 0.0)
    centre = pixel(result.image, [CAMERA.cx, CAMERA.cy])
    assert np.allclose(centre, encoded(0.7), atol=1)


def test_dot_texture_matches_the_circles():
    texture = DotCardTexture(CFG, CODE)
    rng = np.random.default_rng(5)
    xy = rng.uniform(-0.16, 0.16, (20000, 2))
    # Points just inside and just outside every dot edge.
    angles = rng.uniform(0, 2 * np.pi, (CFG.n_dots, 50))
    for scale in (1 - 1e-6, 1 + 1e-6):
        edge = CFG.model_points()[:, None, :2] + scale * CFG.dot_radii()[:, None, None] * (
            np.stack([np.cos(angles), np.sin(angles)], axis=-1))
        xy = np.vstack([xy, edge.reshape(-1, 2)])
    distance = np.linalg.norm(xy[:, None] - CFG.model_points()[None, :, :2], axis=2)
    inside = distance <= CFG.dot_radii()
    ink = ink_reflectance(np.array([CFG.colour_rgb(c) for c in CFG.dot_colours(CODE)]))
    assert np.allclose(ink[1], 0.03) and ink.max() == pytest.approx(0.03 + 0.82 * 0.745, abs=0.01)
    colours = np.vstack([np.full(3, 0.85), ink])
    expected = colours[np.where(inside.any(axis=1), inside.argmax(axis=1) + 1, 0)]
    assert np.allclose(texture.reflectance(xy), expected, atol=1e-6)


@pytest.mark.parametrize('distance, tilt, pan, roll, offset', [
    (1.5, 0.0, 0.0, 0.0, (0.0, 0.0)),
    (2.0, 40.0, 30.0, 0.0, (0.0, 0.0)),
    (0.8, 60.0, -120.0, 15.0, (40.0, -25.0)),
    (3.0, 25.0, 200.0, -30.0, (-100.0, 60.0)),
])
def test_card_pose_facing(distance, tilt, pan, roll, offset):
    camera = CameraModel.from_focal(320, 240, 300.0, D=[-0.1, 0.01, 0.0, 0.0, 0.0])
    pose = card_pose_facing(distance, tilt, pan, roll, offset, camera)
    assert np.allclose(pose.R.T @ pose.R, np.eye(3))
    assert np.linalg.norm(pose.t) == pytest.approx(distance)
    eye = pose.inverse().t  # camera centre in the card frame
    assert math.degrees(math.acos(eye[2] / distance)) == pytest.approx(tilt, abs=1e-9)
    if tilt > 0:
        assert math.degrees(math.atan2(eye[0], eye[1])) % 360 == pytest.approx(pan % 360)
    centre = camera.project(pose.t[None])[0]
    assert np.allclose(centre, [camera.cx + offset[0], camera.cy + offset[1]], atol=1e-6)


@pytest.mark.parametrize('roll', [0.0, 30.0, -75.0])
def test_card_pose_facing_is_upright_then_rolled(roll):
    pose = card_pose_facing(1.0, 35.0, 20.0, roll)
    up = CAMERA.project(pose.apply(np.array([[0.0, 0.0, 0.0], [0.0, 0.01, 0.0]])))
    direction = up[1] - up[0]
    # Upright: card +y straight up; positive roll turns it counter-clockwise.
    assert math.degrees(math.atan2(-direction[1], direction[0])) == pytest.approx(90.0 + roll)


def test_same_seed_same_image_other_seed_other_image():
    card = dot_card(card_pose_facing(0.7, 30.0, 45.0))
    options = RenderOptions(background='clutter', noise_sigma=3.0, shot_noise=0.01, seed=11)
    first = render_scene(CAMERA, [card], options)
    again = render_scene(CAMERA, [card], options)
    other = render_scene(CAMERA, [card], RenderOptions(background='clutter', seed=12))
    assert np.array_equal(first.image, again.image)
    assert not np.array_equal(first.image, other.image)
    # Clutter draws distractors over the whole frame, far from the plain wall.
    wall = render_scene(CAMERA, [], RenderOptions(background='wall', seed=11)).image
    assert np.std(other.image.astype(float)) > 2 * np.std(wall.astype(float))


def test_noise_level():
    options = RenderOptions(background='white', noise_sigma=4.0, seed=3)
    image = render_scene(CAMERA, [], options).image.astype(float)
    assert np.std(image) == pytest.approx(4.0, rel=0.1)
    assert np.mean(image) == pytest.approx(encoded(0.85), abs=0.2)


def test_blur_spreads_dots_along_the_motion():
    card = dot_card(frontal_pose(0.6, (0.0, 0.0)))
    sharp = linear(render_scene(CAMERA, [card], PLAIN).image)
    moved = linear(render_scene(CAMERA, [card], RenderOptions(
        background='black', motion_blur_px=12.0, motion_blur_angle_deg=0.0)).image)
    defocus = linear(render_scene(CAMERA, [card], RenderOptions(
        background='black', defocus_sigma_px=2.0)).image)
    # Blur in linear light keeps the total light (the border is far from the card).
    for blurred in (moved, defocus):
        assert blurred.sum() == pytest.approx(sharp.sum(), rel=0.01)
    # The centre dot (radius 12 px, red: dark in green) is widened by the
    # 12 px horizontal motion to +-18 px along the row, not along the column.
    u, v = np.round([CAMERA.cx, CAMERA.cy]).astype(int)
    paper = sharp[pixel_index(np.array([CAMERA.cx, CAMERA.cy]) - 67)][1]
    row = np.flatnonzero(moved[v, u - 22:u + 23, 1] < 0.9 * paper)
    column = np.flatnonzero(moved[v - 22:v + 23, u, 1] < 0.9 * paper)
    assert column.size <= 26 and row.size >= column.size + 8
    assert np.abs(defocus[v, u - 30:u + 30, 1] - sharp[v, u - 30:u + 30, 1]).max() > 0.1


def test_jpeg_round_trip():
    card = dot_card(frontal_pose())
    plain = render_scene(CAMERA, [card], RenderOptions(seed=2)).image
    jpeg = render_scene(CAMERA, [card], RenderOptions(seed=2, jpeg_quality=85)).image
    assert jpeg.shape == plain.shape and jpeg.dtype == np.uint8
    assert not np.array_equal(jpeg, plain)
    assert np.mean(np.abs(jpeg.astype(float) - plain)) < 3.0


# Handedness marks, mirrors ---------------------------------------------------------------

def test_handedness_marks_are_black_where_the_config_puts_them_and_a_mirror_moves_them():
    texture = DotCardTexture(MARKED, CODE)
    marks, mirrored = MARKED.mark_points(), MARKED.mark_points(mirrored=True)
    black = ink_reflectance(np.array(MARKED.colour_rgb('K')))
    assert np.allclose(texture.reflectance(marks), black)
    assert np.allclose(texture.reflectance(mirrored), 0.85)
    # Just inside and outside a mark's edge.
    r = MARKED.mark_radius
    assert np.allclose(texture.reflectance(marks + [0.999 * r, 0.0]), black)
    assert np.allclose(texture.reflectance(marks + [1.001 * r, 0.0]), 0.85)
    mirror = MirroredTexture(texture)
    assert np.allclose(mirror.reflectance(mirrored), black)
    assert np.allclose(mirror.reflectance(marks), 0.85)
    # From behind through thin paper: the print fades towards the paper.
    faded = MirroredTexture(texture, contrast=0.4)
    assert np.allclose(faded.reflectance(mirrored), 0.85 - 0.4 * (0.85 - black))
    # The dots of the mirror image are the mirrored code's.
    points = MARKED.model_points()[1:9, :2]
    assert np.allclose(mirror.reflectance(points), DotCardTexture(
        MARKED, CODE.mirrored()).reflectance(points))


def test_a_glossy_cards_highlight_adds_the_same_light_over_ink_and_paper():
    texture = DotCardTexture(CFG, CODE)
    glossy = GlossyTexture(texture, (0.04, 0.0), 0.03, 0.6)
    points = np.vstack([CFG.model_points()[:, :2], [[0.04, 0.0], [0.14, 0.14]]])
    added = glossy.reflectance(points) - texture.reflectance(points)
    d2 = np.sum((points - [0.04, 0.0]) ** 2, axis=1)
    assert np.allclose(added, (0.6 * np.exp(-d2 / (2 * 0.03 ** 2)))[:, None])
    # Its peak, far from it nothing; rendered, the sensor clips the peak.
    assert np.isclose(added[-2, 0], 0.6) and np.all(added[-1] < 1e-6)
    pose = frontal_pose()
    plain = render_scene(CAMERA, [CardPlacement(pose, texture, CODE, CFG)]).image
    shiny = render_scene(CAMERA, [CardPlacement(pose, glossy, CODE, CFG)]).image
    peak = CAMERA.project((pose.R @ [0.04, 0.0, 0.0] + pose.t)[None])[0]
    u, v = int(round(peak[0])), int(round(peak[1]))
    assert shiny[v, u].min() == 255 and plain[v, u].max() < 250
    assert np.array_equal(shiny[:20, :20], plain[:20, :20])


# Backgrounds, colour optics, sensor and video ------------------------------------------

@pytest.mark.parametrize('kind', ['texture', 'night', 'photo'])
def test_new_backgrounds_are_seeded_and_look_their_part(kind):
    first = render_scene(CAMERA, [], RenderOptions(background=kind, seed=5)).image
    again = render_scene(CAMERA, [], RenderOptions(background=kind, seed=5)).image
    other = render_scene(CAMERA, [], RenderOptions(background=kind, seed=6)).image
    assert np.array_equal(first, again) and not np.array_equal(first, other)
    grey = first.astype(float).mean(axis=2)
    # Fine texture: neighbouring pixels differ a lot (blur of about a pixel).
    fine = np.abs(np.diff(grey, axis=1)).mean()
    if kind == 'texture':
        assert fine > 8.0
    elif kind == 'night':
        assert np.median(grey) < 70.0
    else:
        assert np.std(grey) > 30.0


def test_channel_shift_and_lateral_colour_move_red_and_blue_only():
    card = dot_card(frontal_pose(0.6, (0.0, 0.0)))
    plain = linear(render_scene(CAMERA, [card], PLAIN).image)
    shifted = linear(render_scene(CAMERA, [card], RenderOptions(
        background='black', channel_shift_px=(2.0, 0.0))).image)
    assert np.allclose(shifted[:, :, 1], plain[:, :, 1], atol=1e-9)     # green stays
    # Red moves right by 2 px, blue left (BGR: red is channel 2).
    assert np.abs(shifted[:, 40:-40, 2] - plain[:, 38:-42, 2]).max() < 0.02
    assert np.abs(shifted[:, 40:-40, 0] - plain[:, 42:-38, 0]).max() < 0.02
    lateral = linear(render_scene(CAMERA, [card], RenderOptions(
        background='black', lateral_ca=0.01)).image)
    assert np.allclose(lateral[:, :, 1], plain[:, :, 1], atol=1e-9)
    assert np.abs(lateral[:, :, 2] - plain[:, :, 2]).max() > 0.1


def test_interlace_moves_the_odd_rows():
    card = dot_card(frontal_pose(0.6, (0.0, 0.0)))
    plain = render_scene(CAMERA, [card], PLAIN).image
    combed = render_scene(CAMERA, [card], RenderOptions(background='black',
                                                        interlace_shift_px=3.0)).image
    assert np.array_equal(combed[0::2], plain[0::2])
    assert np.abs(combed[1::2, 10:-10].astype(int) - plain[1::2, 13:-7]).max() <= 1


def test_crosstalk_greys_colours_and_keeps_the_grey():
    card = dot_card(frontal_pose(0.6, (0.0, 0.0)))
    truth = render_scene(CAMERA, [card], PLAIN).truth[0]
    plain = linear(render_scene(CAMERA, [card], RenderOptions(background='white')).image)
    grey = linear(render_scene(CAMERA, [card], RenderOptions(background='white',
                                                             crosstalk=0.3)).image)
    for centre, letter in zip(truth.dot_pixels, CFG.dot_colours(CODE)):
        a, b = plain[pixel_index(centre)], grey[pixel_index(centre)]
        assert np.ptp(b) <= np.ptp(a) + 1e-3       # less saturated
    assert np.allclose(grey[5, 5], plain[5, 5], atol=0.01)      # white paper stays white


def test_chroma_blur_keeps_the_luma():
    card = dot_card(frontal_pose(0.6, (0.0, 0.0)))
    plain = render_scene(CAMERA, [card], PLAIN).image.astype(float)
    soft = render_scene(CAMERA, [card], RenderOptions(background='black',
                                                      chroma_blur_px=2.0)).image.astype(float)
    luma = [0.114, 0.587, 0.299]                     # BGR
    # The luma stays (but where a blurred colour difference leaves 0..255).
    assert np.abs(plain @ luma - soft @ luma).mean() < 0.3
    assert np.abs(plain - soft).max() > 20.0


@pytest.mark.parametrize('options, words', [
    (RenderOptions(supersample=0), 'supersample'),
    (RenderOptions(background='forest'), 'background'),
    (RenderOptions(gain=-1.0), 'gain'),
    (RenderOptions(crosstalk=0.7), 'crosstalk'),
    (RenderOptions(lateral_ca=0.5), 'lateral_ca'),
    (RenderOptions(channel_shift_px=(1.0,)), 'channel_shift_px'),
    (RenderOptions(chroma_blur_px=-1.0), 'chroma_blur_px'),
    (RenderOptions(interlace_shift_px=float('nan')), 'interlace_shift_px'),
    (RenderOptions(jpeg_quality=0), 'jpeg_quality'),
    (RenderOptions(occluders=(Occluder(3, np.zeros((4, 2))),)), 'card_index'),
    (RenderOptions(occluders=(Occluder(0, np.zeros((2, 2))),)), 'polygon_xy'),
])
def test_bad_options_are_config_errors(options, words):
    with pytest.raises(ConfigError, match=words):
        render_scene(CAMERA, [dot_card(frontal_pose())], options)


def test_bad_inputs_raise_package_errors():
    with pytest.raises(ImageError):
        BitmapCardTexture(np.zeros((4, 4), dtype=np.float32), 0.1)
    with pytest.raises(ConfigError):
        BitmapCardTexture(np.zeros((4, 4), dtype=np.uint8), 0.0)
    with pytest.raises(CodeError):
        DotCardTexture(CFG, Code('X', 'KRGBRGBR'))
    with pytest.raises(ConfigError, match='contrast'):
        MirroredTexture(DotCardTexture(CFG, CODE), contrast=0.0)
    for centre, sigma, level, what in (((0.0, 0.0), 0.0, 0.5, 'sigma'),
                                       ((0.0, 0.0), 0.05, -0.1, 'level'),
                                       ((0.0, math.nan), 0.05, 0.5, 'centre'),
                                       ((0.0,), 0.05, 0.5, 'centre')):
        with pytest.raises(ConfigError, match=what):
            GlossyTexture(DotCardTexture(CFG, CODE), centre, sigma, level)
    with pytest.raises(ConfigError, match='view_angle'):
        card_pose_facing(1.0, 90.0, 0.0)
    with pytest.raises(ConfigError, match='camera'):
        card_pose_facing(1.0, 10.0, 0.0, offset_px=(5.0, 0.0))
    with pytest.raises(ConfigError, match='rotation'):
        render_scene(CAMERA, [dot_card(Pose(2 * np.eye(3), np.zeros(3)))])
