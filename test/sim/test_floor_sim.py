"""Frames of the floor sim: motion blur, interlace, truth, and the one-room paper option."""

import math

import numpy as np
from pattern_locator.errors import ConfigError
from pattern_locator.sim.drive import yaw_pose
from pattern_locator.sim.floor_scene import Field
from pattern_locator.sim.floor_sim import Exposure, FloorSim, HeadTrack
from pattern_locator.sim.world import SimScene
from pattern_locator.visca.zoom_table import ZoomTable
from pattern_locator.vision.locate import CardLocator
import pytest

TABLE = ZoomTable.load()
CARD = (4, 3, 1)              # room 3's west wall, (2.3, 10.0)


class PlainPaper:
    """A card face with no dots: the same box, the same light, only paper."""

    def __init__(self, size, paper):
        self.size = size
        self._paper = paper

    def reflectance(self, xy):
        return np.full((len(xy), 3), self._paper, dtype=np.float32)


def panning(scene, rate, zoom=300):
    """Return the camera, and camera poses at time t of a head panning at ``rate`` rad/s."""
    base = yaw_pose(7.0, 10.0, math.pi, scene.world.z)
    pan, tilt = scene.card_angles(base, 0.0, 0.0, CARD)
    return TABLE.camera_at(zoom), lambda t: scene.true_camera_pose(base, pan + rate * t, tilt)


def darkness(scene, camera, fields):
    """
    Return the card's darkness per pixel (linear light) and the reported blur.

    Measured against the same frame with the card's dots left out, so that
    only the dots count.
    """
    image, blurs = scene.render(camera, fields, seed=1)
    face = scene._face(scene.world.card(CARD))
    scene._faces[CARD] = PlainPaper(face.size, 0.85)
    try:
        paper, _ = scene.render(camera, fields, seed=1)
    finally:
        scene._faces[CARD] = face
    return (paper / 255.0) ** 2.2 - (image / 255.0) ** 2.2, blurs


def spread_x(dark):
    """Return the centroid and variance along x of a darkness image (summed over colours)."""
    d = dark.sum(axis=2)
    x = np.arange(d.shape[1])[None, :]
    mean = (d * x).sum() / d.sum()
    return mean, (d * (x - mean) ** 2).sum() / d.sum()


def test_motion_blur_length_matches_the_motion(quiet_scene):
    exposure = 0.02
    camera, at = panning(quiet_scene, 0.0)
    _, still = spread_x(darkness(quiet_scene, camera, [Field.still(at(0.0))])[0])
    for rate in (0.4, 0.7):
        camera, at = panning(quiet_scene, rate)
        fields = [Field(at(-exposure / 2), at(0.0), at(exposure / 2))]
        dark, blurs = darkness(quiet_scene, camera, fields)
        # The motion: the card's centre moves by about fx * rate * exposure.
        assert blurs[CARD] == pytest.approx(camera.fx * rate * exposure, rel=0.03)
        # The image: a uniform smear of length L adds L^2 / 12 to the variance
        # along the motion (the kernel's sampling adds a little more).
        length = math.sqrt(12.0 * (spread_x(dark)[1] - still))
        assert length == pytest.approx(blurs[CARD], rel=0.05)
    # No motion, no blur: the frame of a still camera.
    image, blurs = quiet_scene.render(camera, [Field.still(at(0.0))], seed=4)
    assert blurs[CARD] == 0.0
    np.testing.assert_array_equal(image, quiet_scene.render_still(at(0.0), camera, seed=4))


def test_blur_from_the_base_driving_past_cards(floor_world):
    sim = FloorSim(floor_world, floor_world.route('short'), exposure=Exposure(0.04))
    # Driving west through room 3 at 0.3 m/s, the head still: the blur is
    # parallax, the base's motion across the line of sight over the exposure.
    track = sim.route.track(0.05)
    t = float(next(row[0] for row in track if row[1] < 7.3 and row[2] > 9.99))
    state = sim.state(t)
    assert state.speed_m_s == pytest.approx(0.3) and state.yaw_rate_rad_s == 0.0
    velocity = state.speed_m_s * np.array([math.cos(state.heading), math.sin(state.heading), 0])
    camera = TABLE.camera_at(300)
    blurs = {}
    # Card 3.1 straight ahead (on the west wall), 3.3 and 3.4 abeam (north, south).
    for ids in ((4, 3, 1), (4, 3, 3), (4, 3, 4)):
        card = floor_world.card(ids)
        aim = sim.scene.card_angles(state.pose, 0.0, 0.0, ids)
        frame = sim.frame(t, lambda _: aim, camera, seed=1)
        line = card.T_building_card.t - frame.truth.T_building_camera.t
        distance = np.linalg.norm(line)
        across = np.linalg.norm(np.cross(velocity, line / distance))
        expected = camera.fx * across * 0.04 / distance
        blurs[ids] = dict(frame.truth.blur_px)[ids]
        assert blurs[ids] == pytest.approx(expected, rel=0.05), ids
    # Ahead the card mostly grows; abeam it sweeps past.
    assert min(blurs[(4, 3, 3)], blurs[(4, 3, 4)]) > 3.0 * blurs[(4, 3, 1)] > 1.0


def test_interlace_fields_differ_by_the_motion_between_them(quiet_scene):
    rate, period = 0.5, 0.02
    camera, at = panning(quiet_scene, rate)
    exposure = Exposure(0.01, interlace=True, field_period_s=period)
    fields = [Field(at(a), at((a + b) / 2.0), at(b)) for a, b in exposure.windows(0.0)]
    assert exposure.windows(0.0) == [(-0.015, -0.005), (0.005, 0.015)]
    assert exposure.latest_stamp(0.015) == pytest.approx(0.0)
    dark, _ = darkness(quiet_scene, camera, fields)
    even, _ = spread_x(dark[0::2])
    odd, _ = spread_x(dark[1::2])
    # Panning left (+ pan) moves the card right in the image: the later field
    # (odd rows) shows it fx * rate * period further right.
    assert odd - even == pytest.approx(camera.fx * rate * period, rel=0.05)
    still = [Field.still(at(0.0))] * 2
    dark, _ = darkness(quiet_scene, camera, still)
    assert abs(spread_x(dark[1::2])[0] - spread_x(dark[0::2])[0]) < 0.05


def test_a_frame_and_its_truth_locate_the_robot(floor_world):
    sim = FloorSim(floor_world, floor_world.route('short'), seed=2)
    # Driving west through room 3.
    track = sim.route.track(0.1)
    t = float(next(row[0] for row in track if row[1] < 8.0 and row[2] > 9.9))
    state = sim.state(t)
    camera = TABLE.camera_at(300)
    aim = sim.scene.card_angles(state.pose, 0.0, 0.0, (4, 3, 3))
    head = HeadTrack()
    head.add(t - 0.1, aim[0] - 0.01, aim[1])
    head.add(t + 0.1, aim[0] + 0.01, aim[1])        # panning at 0.1 rad/s
    frame = sim.frame(t, head, camera, seed=3)
    truth = frame.truth
    assert truth.room == (4, 3) and truth.phase == 'drive' and truth.stamp_s == t
    assert truth.pan == pytest.approx(aim[0]) and truth.target.as_tuple() == (4, 3, 3)
    assert truth.target_in_view
    assert truth.target_angles == pytest.approx((0.0, 0.0), abs=1e-9)
    np.testing.assert_allclose(truth.T_building_base.t, state.pose.t)
    np.testing.assert_allclose(truth.T_building_camera.matrix(), (
        state.pose @ sim.scene.head.T_base_camera(truth.pan, truth.tilt)).matrix())
    assert truth.exposures == ((t - 0.01, t + 0.01),)
    assert 1.0 < dict(truth.blur_px)[(4, 3, 3)] < 10.0
    view = {v.ids.as_tuple(): v for v in truth.views}[(4, 3, 3)]
    assert view.complete and view.off_axis_deg < 0.01
    located = [c for c in CardLocator(floor_world.pattern).locate(frame.image, camera)
               if c.T_camera_pattern is not None]
    assert [c.detection.ids.as_tuple() for c in located] == [(4, 3, 3)]
    card = floor_world.card((4, 3, 3)).T_building_card
    truth_camera_in_card = (card.inverse() @ truth.T_building_camera).t
    assert np.linalg.norm(located[0].camera_in_pattern - truth_camera_in_card) < 0.05
    # Odometry rides along: samples up to the frame's time, odom = start pose.
    samples = sim.odometry(t)
    assert len(samples) == int(round(t * 50)) + 1
    np.testing.assert_allclose(sim.T_building_odom.t, sim.state(0.0).pose.t)


def test_the_paper_room_is_still_there(floor_world):
    # FloorSim's paper option: the room of world.SimScene, with its walls, in the
    # building frame; it renders the same images.
    sim = FloorSim.paper(mode='stops', dwell_s=2.0, n_stops=3)
    scene = SimScene()
    room = scene.room.T_building_room
    camera = TABLE.camera_at(0)
    for k, stop in enumerate(sim.route.route.stops):
        t = 2.0 * k + 1.0
        np.testing.assert_allclose(sim.state(t).pose.matrix(),
                                   (room @ stop.pose()).matrix(), atol=1e-12)
        pan, tilt = scene.card_angles(stop.pose(), 0.0, 0.0, stop.card)
        frame = sim.frame(t, lambda _: (pan, tilt), camera, seed=k)
        assert frame.truth.target.as_tuple() == (1, 3, stop.card)
        assert frame.truth.room == (1, 3) and frame.truth.blur_px[0][1] == 0.0
        expected = scene.render(stop.pose(), pan, tilt, camera, seed=k)
        assert np.abs(frame.image.astype(int) - expected).max() <= 1
    away = sim.frame(100.0, lambda _: (0.0, -0.4), camera).truth     # at the floor
    assert away.phase == 'stop' and away.views == () and not away.target_in_view
    assert away.target is not None and max(np.abs(away.target_angles)) > 0.3
    driving = FloorSim.paper(mode='drive', dwell_s=1.0, n_stops=3)
    t = driving.route.route.dwell_window(0)[1] + 1.0
    # That route moves sideways as it turns (a holonomic base): speed is forward only.
    moved = np.linalg.norm(driving.state(t + 0.1).pose.t - driving.state(t).pose.t)
    assert driving.state(t).phase == 'drive' and moved > 0.01


def test_head_track_interpolates_and_holds():
    track = HeadTrack(max_extrapolation_s=0.1)
    with pytest.raises(ConfigError, match='no samples'):
        track(0.0)
    track.add(0.0, 3.1, 0.0)
    assert track(5.0) == (3.1, 0.0)
    track.add(0.1, -3.1, 0.1)           # across +-pi: the short way round
    pan, tilt = track(0.05)
    assert abs(abs(pan) - math.pi) < 1e-9 and tilt == pytest.approx(0.05)
    assert track(0.15)[1] == pytest.approx(0.15)
    assert track(9.0)[1] == pytest.approx(0.2)      # extrapolates 0.1 s, then holds


def test_a_shorter_shutter_trades_blur_for_noise(floor_world):
    # The camera's auto exposure makes up a shorter shutter's light with gain
    # (Exposure.image_options): the cards smear less, the noise grows with the
    # gain; past the top gain the image darkens.
    camera = TABLE.camera_at(300)
    base = yaw_pose(7.0, 10.0, math.pi, floor_world.z)
    frames = {}
    for shutter in (0.02, 0.004, 0.001):
        sim = FloorSim(floor_world, floor_world.route('short'), exposure=Exposure(shutter))
        pan, tilt = sim.scene.card_angles(base, 0.0, 0.0, CARD)
        sim._base_pose = lambda t, stamp: base
        shots = [sim.render(0.0, lambda t: (pan + 0.5 * t, tilt), camera, seed)  # 0.5 rad/s
                 for seed in (1, 2)]
        # The wall in the top rows (no card there): two seeds' noise differs.
        wall = [image[:40].astype(float) for image, _ in shots]
        frames[shutter] = (np.std(wall[0] - wall[1]) / math.sqrt(2.0), wall[0].mean(),
                           shots[0][1][CARD])
    noise, level, blur = frames[0.02]
    assert blur == pytest.approx(camera.fx * 0.5 * 0.02, rel=0.03)
    assert frames[0.004][2] == pytest.approx(blur / 5.0, rel=0.03)
    assert frames[0.004][0] == pytest.approx(5.0 * noise, rel=0.15)
    assert frames[0.004][1] == pytest.approx(level, abs=1.0)
    # 1 ms needs a gain of 20: the camera stops at 7.94 and the wall darkens.
    assert frames[0.001][0] == pytest.approx(7.94 * noise, rel=0.15)
    assert frames[0.001][1] < level - 30.0
    assert Exposure(0.04).image_options(sim.scene.options) == sim.scene.options
    with pytest.raises(ConfigError):
        Exposure(0.004, max_gain=0.5)
