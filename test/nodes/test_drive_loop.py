"""
The drive through the floor in closed loop: sim, camera_driver and locator as processes.

One run on the first 23 s of the floor's ``short`` route (along the south
corridor, round a corner through room 3's door and into the room), checked
for several things at once: the fixes, the odometry, the logs, and the sim's
own time (the sim publishes ``/clock``, every node runs with
``use_sim_time``, as ``sim.launch.py use_sim_time:=true`` has it). Real
processes over DDS, a real pseudo-terminal; no timing is asserted.
"""

import math

import numpy as np
from pattern_locator.evaluation.drive_demo import DriveSetup, judge, run_drive
from pattern_locator.sim.floor_file import load_floor_world
import pytest

UNTIL_S = 23.0
# The sim's world runs at 0.4 of the wall's pace (its real-time factor, on its
# /clock): the sim renders a frame in 30-80 ms on a quiet machine, but on a
# slow 2-core one beside the locator and the driver in 260-290 ms (median),
# under 2 frames a second of the wall (43 images where 69 were asked). Slowed,
# a slow machine gives the stack the frames of each second of its time that a
# faster computer would.
REAL_TIME_FACTOR = 0.4


@pytest.fixture(scope='module')
def short_drive(tmp_path_factory):
    out = tmp_path_factory.mktemp('drive')
    setup = DriveSetup(route='short', until_s=UNTIL_S, record_odometry=True, timeout_s=180.0,
                       camera_init_s=0.3, sim_time=True, real_time_factor=REAL_TIME_FACTOR)
    observer = run_drive(out, setup)
    world = load_floor_world()
    return out, observer, judge(observer, world, until_s=UNTIL_S), world


def test_the_short_route_locates_the_robot_and_never_a_wrong_card(short_drive):
    out, observer, metrics, _ = short_drive
    # The sim drove on its own clock (seconds since it started, not the epoch):
    # images all along the 23 s, in the corridor and in room 3.
    begin, _ = observer.route_window()
    assert 0 < begin < 60e9, begin
    # The sim skips frames while the machine is busy, even slowed: at least 3
    # of the 10 a second of its time.
    assert metrics.images >= 0.3 * UNTIL_S * 10, metrics.images
    assert observer.sim_status['real time factor'] == f'{REAL_TIME_FACTOR:g}'
    rooms = {r.name.split()[0]: r for r in metrics.rooms}
    assert {'9', '3'} <= set(rooms), list(rooms)
    # Never a card that was not in the image (a wall or a jamb hid it, or it
    # was misread): the sim's world, at the true camera pose, says which were.
    assert metrics.wrong_ids == 0
    assert metrics.unpaired == 0
    # The locator's own counts and stage times reach the summary (what explains
    # the coverage: frames dropped while busy, rejections, time per frame).
    assert int(metrics.locator['received']) >= metrics.images // 2, metrics.locator
    # The driver set the camera's shutter (1/250 s) and the sim exposes with
    # what the emulated camera does.
    assert observer.sim_status['exposure ms'] == '4', observer.sim_status
    assert 'processing_ms_median' in metrics.locator, metrics.locator
    # Bounds the system meets today, with the margin a loaded 2-core machine
    # needs (the final targets, 95 % and 1/3/10 cm, need the map-guided
    # gaze and the locator's odometry): the head loses its card where the robot
    # turns into the door and searches, so 30-60 % of the time has a fix.
    assert metrics.located >= 30, metrics.located
    assert metrics.fix_coverage >= 0.15, metrics.fix_coverage
    e = metrics.error_summary()
    assert e['median'] <= 0.02 and e['p95'] <= 0.10 and e['max'] <= 0.5, e
    # Fixes in the corridor and in the room, each within a few cm at its median.
    for name in ('9', '3'):
        assert rooms[name].fixes >= 5 and np.median(rooms[name].errors_m) < 0.03, name
    # The covariance is not wildly over-confident: most errors lie in their ellipsoid.
    assert metrics.coverage_95 >= 0.5, metrics.coverage_95
    # The head holds a card it tracks near the centre (within the head's travel).
    assert metrics.off_axis_deg.size >= 10
    assert np.median(metrics.off_axis_deg) < 2.0, np.median(metrics.off_axis_deg)
    for log in ('sim.log', 'camera_driver.log', 'locator.log'):
        text = (out / log).read_text()
        assert 'Traceback' not in text, (log, text[-2000:])


def test_the_sim_publishes_odometry_that_drifts_within_its_covariance(short_drive):
    _, observer, _, world = short_drive
    begin, _ = observer.route_window()
    end = begin + int(UNTIL_S * 1e9)
    odometry = sorted((s for s in observer.odometry if begin <= s[0] <= end),
                      key=lambda s: s[0])
    # 50 Hz over the whole window (a message lost now and then on a busy machine).
    assert len(odometry) >= 0.8 * 50 * UNTIL_S, len(odometry)
    truth = sorted((k, f.T_building_base) for k, f in observer.frames.items()
                   if f.T_building_base is not None and begin <= k <= end)
    # The odom frame is where the base stood when the route started (it stands
    # still for its first second).
    T_odom_building = truth[0][1].inverse()
    stamps = np.array([s[0] for s in odometry])

    def odometry_at(stamp):
        return odometry[int(np.argmin(np.abs(stamps - stamp)))]

    # The path: 2 % longer in the odometry (its scale error), as configured.
    # The true path from the route itself, finely (the images that carry the
    # truth come fewer on a busy machine, and their chords cut the corners).
    first, last = odometry_at(truth[0][0]), odometry_at(truth[-1][0])
    route = world.route('short')
    times = np.arange((first[0] - begin) * 1e-9, (last[0] - begin) * 1e-9, 0.01)
    true_xy = np.array([route.state_at(float(t)).pose.t[:2] for t in times])
    true_length = float(np.sum(np.linalg.norm(np.diff(true_xy, axis=0), axis=1)))
    odom_xy = np.array([s[1].t[:2] for s in odometry if first[0] <= s[0] <= last[0]])
    odom_length = float(np.sum(np.linalg.norm(np.diff(odom_xy, axis=0), axis=1)))
    assert true_length > 5.0, true_length
    assert odom_length / true_length == pytest.approx(1.02, abs=0.006)
    # At the end the odometry is off the truth by centimetres, and its own
    # covariance (which grows along the way) says so: within 3 sigma.
    stamp, T_true = truth[-1]
    _, T_odom, covariance = odometry_at(stamp)
    drift = (T_odom.t - (T_odom_building @ T_true).t)[:2]
    assert np.linalg.norm(drift) > 0.03, drift
    sigma = covariance[:2, :2]
    assert float(drift @ np.linalg.solve(sigma, drift)) < 3.0 ** 2 * 2, (drift, sigma)
    assert covariance[0, 0] > odometry[0][2][0, 0] and math.isfinite(covariance[5, 5])
