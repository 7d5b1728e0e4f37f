"""The simulated floor: its cards come from the map, walls hide them, doors let some through."""

import math

import numpy as np
from pattern_locator.errors import ConfigError
from pattern_locator.localization.building import load_building
from pattern_locator.resources import config_path
from pattern_locator.sim.drive import yaw_pose
from pattern_locator.sim.floor_file import load_floor_world
from pattern_locator.sim.floor_scene import FloorScene
from pattern_locator.sim.floor_world import FloorWorld
from pattern_locator.sim.plan_plot import plot_floor_plan
from pattern_locator.visca.zoom_table import ZoomTable
from pattern_locator.vision.geometry import rotation_angle
from pattern_locator.vision.locate import CardLocator
import pytest
import yaml

TABLE = ZoomTable.load()
CORRIDORS = {9, 10, 11, 12, 13, 14}


def test_the_floors_cards_load_from_the_building_map(floor_world):
    building = load_building(config_path('floor_building.yaml'))
    mapped = [c for c in building.cards() if c.ids.floor == floor_world.floor]
    assert [c.ids for c in floor_world.cards] == [c.ids for c in mapped]
    for card, entry in zip(floor_world.cards, mapped):
        assert card.code == entry.code
        # Hung where the map says: the truth is the map's pose.
        np.testing.assert_allclose(card.T_building_card.matrix(),
                                   entry.T_building_card.matrix(), atol=1e-12)
        assert card.T_building_card.t[2] - floor_world.z == pytest.approx(2.15)
    assert len(floor_world.cards) >= 30
    rooms = {c.ids.room for c in floor_world.cards}
    assert len(rooms - CORRIDORS) >= 6 and CORRIDORS <= rooms
    # Every card faces into the room it belongs to: just in front of it is that room.
    for card in floor_world.cards:
        ahead = card.T_building_card.t + 0.3 * card.T_building_card.R[:, 2]
        assert floor_world.room_at(ahead[:2]).room == card.ids.room, card.ids


def test_the_corridors_make_a_loop_of_more_than_60_m(floor_world):
    # The tour goes round the loop back to its start; its corridor part is >= 60 m.
    route = floor_world.route('tour')
    track = route.track(0.1)
    np.testing.assert_allclose(track[0, 1:3], track[-1, 1:3], atol=1e-9)
    steps = np.linalg.norm(np.diff(track[:, 1:3], axis=0), axis=1)
    rooms = floor_world.rooms_at(track[:-1, 1:3])
    assert steps[np.isin(rooms, list(CORRIDORS))].sum() > 60.0
    visited = set(rooms.tolist()) - {0}
    assert CORRIDORS <= visited and len(visited - CORRIDORS) >= 4


def test_as_hung_cards_are_off_the_map_by_a_few_cm_and_degrees(floor_world):
    exact = floor_world
    hung = floor_world.as_hung(11)
    again = floor_world.as_hung(11)
    other = floor_world.as_hung(12)
    shifts, turns = [], []
    half = exact.pattern.card_size / 2.0
    for a, b, c, d in zip(exact.cards, hung.cards, again.cards, other.cards):
        assert a.map_card is not None and b.map_card.ids == a.ids
        # The map is unchanged: only where the card really hangs moves.
        np.testing.assert_array_equal(b.map_card.T_building_card.t, a.T_building_card.t)
        np.testing.assert_array_equal(b.T_building_card.t, c.T_building_card.t)
        off = a.T_building_card.inverse() @ b.T_building_card
        shifts.append(np.linalg.norm(off.t))
        turns.append(math.degrees(rotation_angle(off.R, np.eye(3))))
        assert not np.allclose(d.T_building_card.t, b.T_building_card.t)
        # Never into the wall: every corner stays in front of the mapped face.
        corners = off.apply(np.array([[-half, -half, 0], [half, -half, 0], [half, half, 0],
                                      [-half, half, 0]], dtype=float))
        assert corners[:, 2].min() > 0.0
    assert max(shifts) <= 0.05 + 1e-12 and max(turns) <= 3.0 + 1e-9
    assert np.median(shifts) > 0.015 and np.median(turns) > 1.0
    # The loader hangs them the same way.
    loaded = load_floor_world(as_hung_seed=11, building=floor_world.building)
    for a, b in zip(loaded.cards, hung.cards):
        np.testing.assert_array_equal(a.T_building_card.R, b.T_building_card.R)


def camera_at(scene, x, y, heading, ids, zoom=400):
    """Return the base, head angles and camera aimed at card ``ids`` from (x, y)."""
    base = yaw_pose(x, y, heading, scene.world.z)
    pan, tilt = scene.card_angles(base, 0.0, 0.0, ids)
    return base, pan, tilt, TABLE.camera_at(zoom)


def found_ids(image, camera, pattern):
    located = CardLocator(pattern).locate(image, camera)
    return sorted(c.detection.ids.as_tuple() for c in located
                  if c.T_camera_pattern is not None and c.detection.ids is not None)


def test_a_wall_hides_a_card(floor_world, quiet_scene):
    # From room 3, card 10.1 (west corridor, x = 0.1) is straight behind the
    # room's west wall (x = 2.1 .. 2.3); card 3.1 hangs on that wall's room side.
    base, pan, tilt, camera = camera_at(quiet_scene, 7.0, 11.5, math.pi, (4, 10, 1))
    T_camera = quiet_scene.true_camera_pose(base, pan, tilt)
    eye = T_camera.t
    behind = floor_world.card((4, 10, 1))
    assert floor_world.blocked(eye[None], behind.T_building_card.t[None])[0]
    assert floor_world.hidden(behind, floor_world.occluders(behind, eye))
    assert not floor_world.visible_dots(behind, eye).any()
    views = {v.ids.as_tuple(): v for v in quiet_scene.views(T_camera, camera)}
    assert (4, 10, 1) not in views and views[(4, 3, 1)].complete
    image = quiet_scene.render_still(T_camera, camera, seed=2)
    assert found_ids(image, camera, floor_world.pattern) == [(4, 3, 1)]
    # The same view without that wall: the card behind it is there and found.
    open_plan = FloorWorld(floor_world.building, floor_world.pattern, floor_world.floor,
                           floor_world.z, [w for w in floor_world.walls
                                           if not w.name.startswith('west corridor')],
                           floor_world.obstacles, floor_world.cards)
    scene = FloorScene(open_plan, options=quiet_scene.options)
    assert (4, 10, 1) in {v.ids.as_tuple() for v in scene.views(T_camera, camera)}
    image = scene.render_still(T_camera, camera, seed=2)
    assert found_ids(image, camera, floor_world.pattern) == [(4, 3, 1), (4, 10, 1)]


def test_through_a_door_only_what_the_geometry_allows(floor_world):
    # In the south corridor in front of room 3's door (x 8.5 .. 9.5, y 7.3 .. 7.5).
    eye = np.array([9.0, 6.3, floor_world.z + 1.1])
    north = floor_world.card((4, 3, 3))      # (7.3, 12.5): straight through the door
    west = floor_world.card((4, 3, 1))       # (2.3, 10.0): behind the wall
    east = floor_world.card((4, 3, 2))       # (12.3, 10.0): behind the wall
    assert floor_world.visible_dots(north, eye).all()
    assert not floor_world.visible_dots(west, eye).any()
    assert not floor_world.visible_dots(east, eye).any()
    # The lintel (2.0 .. 2.5 m) hides what is seen through the door above 2 m.
    low = np.array([9.0, 5.4, floor_world.z + 1.0])
    above = np.array([9.0, 7.7, floor_world.z + 2.3])     # crosses the door at 2.07-2.18 m
    below = np.array([9.0, 7.7, floor_world.z + 1.9])     # crosses it at 1.75-1.82 m
    assert list(floor_world.blocked(np.array([low, low]), np.array([above, below]))) == [
        True, False]
    # Partly through the door: the shadows of the jambs (polygon path) agree
    # dot by dot with lines of sight cut by the walls (segment path), from
    # corridor positions near rooms 3's and 4's doors (two where a jamb cuts
    # card 3.3).
    rng = np.random.default_rng(5)
    eyes = [(8.8, 6.3, 1.1), (10.2, 5.6, 1.1)] + [
        (door + rng.uniform(-2.5, 2.5), rng.uniform(5.7, 6.9), rng.uniform(1.0, 1.3))
        for door in rng.choice([9.0, 15.8], 18)]
    partial = checked = 0
    for x, y, height in eyes:
        eye = np.array([x, y, floor_world.z + height])
        for card in floor_world.cards:
            if card.ids.room not in (3, 4) or not floor_world.camera_in_front(card, eye):
                continue
            seen = floor_world.visible_dots(card, eye)
            dots = card.T_building_card.apply(floor_world.pattern.model_points())
            cut = floor_world.blocked(np.repeat(eye[None], len(dots), axis=0), dots)
            np.testing.assert_array_equal(seen, ~cut)
            partial += 0 < seen.sum() < len(seen)
            checked += 1
    assert checked > 50 and partial >= 2


def test_a_jamb_hides_part_of_a_card_in_the_image(floor_world, quiet_scene):
    # Card 3.3 seen from the corridor beside room 3's door: the jamb cuts it.
    base = yaw_pose(8.8, 6.3, math.pi / 2, floor_world.z)
    card = floor_world.card((4, 3, 3))
    pan, tilt = quiet_scene.card_angles(base, 0.0, 0.0, (4, 3, 3))
    camera = TABLE.camera_at(450)
    T_camera = quiet_scene.true_camera_pose(base, pan, tilt)
    seen = floor_world.visible_dots(card, T_camera.t)
    assert 3 <= seen.sum() <= 14
    view = {v.ids.as_tuple(): v for v in quiet_scene.views(T_camera, camera)}[(4, 3, 3)]
    assert view.dots_visible == seen.sum() and not view.complete
    image = quiet_scene.render_still(T_camera, camera, seed=1).astype(float)
    points = floor_world.pattern.model_points()
    pixels = camera.project((T_camera.inverse() @ card.T_building_card).apply(points))
    shadow = floor_world.occluders(card, T_camera.t)
    wall = np.median(image.reshape(-1, 3), axis=0)
    checked = {True: 0, False: 0}
    for dot, ok, (u, v) in zip(range(len(seen)), seen, pixels):
        # Only dots clear of the shadow's edge: a dot it cuts is half of each.
        edge = min(_distance_to_boundary(points[dot, :2], p) for p in shadow)
        if edge < floor_world.pattern.dot_radii()[dot] + 0.005:
            continue
        patch = image[int(round(v)) - 1:int(round(v)) + 2, int(round(u)) - 1:int(round(u)) + 2]
        difference = np.abs(patch - wall).max()
        # A seen dot shows its ink; a hidden one is the wall's paint.
        assert (difference > 60) if ok else (difference < 8), (dot, ok, difference)
        checked[bool(ok)] += 1
    assert checked[True] >= 5 and checked[False] >= 3


def _distance_to_boundary(point, polygon):
    """Return the distance from a point to a polygon's outline."""
    a, b = polygon, np.roll(polygon, -1, axis=0)
    ab = b - a
    f = np.clip(np.einsum('ij,ij->i', point - a, ab) / np.einsum('ij,ij->i', ab, ab), 0, 1)
    return float(np.min(np.linalg.norm(a + f[:, None] * ab - point, axis=1)))


@pytest.mark.parametrize('edit, message', [
    (lambda d: d['walls'][0].update(colour='red'), "unknown key 'colour'"),
    (lambda d: d['walls'][4]['doors'][0].update(centre=[6.0, 5.6]), 'off the wall'),
    (lambda d: d['walls'].pop(2), 'floor 4 room 1 card 1 does not hang flat'),
    (lambda d: d['routes']['short'][3].update(xy=[5.0, 12.4]),
     'route short passes 0.10 m from a wall'),
])
def test_bad_world_files_say_what_is_wrong(floor_world, tmp_path, edit, message):
    data = yaml.safe_load(config_path('sim_floor.yaml').read_text())
    data['building_map'] = str(config_path('floor_building.yaml'))
    edit(data)
    path = tmp_path / 'floor.yaml'
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match=message):
        load_floor_world(path, building=floor_world.building).route('short')


def test_the_plan_plot(floor_world):
    track = floor_world.route('short').track(0.5)[:, 1:3]
    ax = plot_floor_plan(floor_world, tracks={'true': track}, points={'fixes': track[::5]})
    labels = {t.get_text() for t in ax.texts}
    assert {f'{c.ids.room}.{c.ids.pattern}' for c in floor_world.cards} <= labels
    xmin, ymin, xmax, ymax = floor_world.bounds()
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    assert x0 < xmin and x1 > xmax and y0 < ymin and y1 > ymax
    assert ax.get_aspect() == 1.0 and 'm' in ax.get_xlabel() and 'm' in ax.get_ylabel()
    assert [line.get_label() for line in ax.get_legend().get_lines()] == ['true', 'fixes']
    np.testing.assert_allclose(ax.get_legend().axes.lines[-2].get_xydata(), track)
