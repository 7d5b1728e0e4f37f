"""Printable cards: true scale, dot geometry and colours, tiles, PDF and PNG structure."""

import math
import re
import struct
import xml.etree.ElementTree as ET
import zlib

import cv2
import numpy as np
# The package is not declared an application import, so it sorts as third party.
from pattern_locator.card.pattern import Ids, PatternConfig
from pattern_locator.card.printable import (CardSheet, Circle, layout_card, Line, MARGIN_MM,
                                            OVERLAP_MM, PAPER_SIZES_MM, pdf_document, png_bytes,
                                            png_image, PrintError, PT_PER_MM, Rect, svg_document,
                                            Text, tile_paths, write_card)
from pattern_locator.errors import CodeError, ConfigError, PatternLocatorError
import pytest

SVG = '{http://www.w3.org/2000/svg}'
IDS = Ids(2, 17, 3)
NOTES = ('label', 'scale-bar', 'scale-tick', 'scale-text', 'up-mark', 'tile-text', 'note',
         'registration')


def small_config() -> PatternConfig:
    # Other radii, other card size and other colours: all must be honoured.
    return PatternConfig(
        card_size=0.200, ring_radii=(0.080, 0.050), ring_dot_radius=0.010,
        centre_dot_radius=0.015,
        colours_rgb=(('K', (10, 10, 10)), ('R', (200, 30, 40)), ('G', (20, 150, 70)),
                     ('B', (30, 60, 190))))


def big_config() -> PatternConfig:
    # Needs 2 x 2 A4 tiles, with a cut line through the middle column of dots.
    return PatternConfig(card_size=0.400, ring_radii=(0.160, 0.100), ring_dot_radius=0.018,
                         centre_dot_radius=0.030)


def expected_dots(config: PatternConfig, ids: Ids) -> dict:
    """Dot name -> (x, y, r, '#rrggbb') in poster mm (origin centre dot, y down)."""
    code = config.encode(ids.floor, ids.room, ids.pattern)
    out = {}
    triples = zip(config.model_points(), config.dot_radii(), config.dot_colours(code))
    for index, (p, r, letter) in enumerate(triples):
        ring, point = config.dot_ring_point(index)
        name = 'dot-centre' if ring is None else f'dot-r{ring}-p{point}'
        out[name] = (p[0] * 1000, -p[1] * 1000, r * 1000,
                     '#{:02x}{:02x}{:02x}'.format(*config.colour_rgb(letter)))
    return out


def svg_root(text: str) -> ET.Element:
    return ET.fromstring(text.encode('utf-8'))


def svg_dots(root: ET.Element, role: str = 'dot') -> dict:
    dots = {}
    for c in root.iter(SVG + 'circle'):
        if c.get('class') == role:
            dots[c.get('id')] = (float(c.get('cx')), float(c.get('cy')), float(c.get('r')),
                                 c.get('fill'))
    return dots


def by_id(root: ET.Element, name: str) -> ET.Element:
    found = [e for e in root.iter() if e.get('id') == name]
    assert len(found) == 1, name
    return found[0]


def item_box(item):
    if isinstance(item, Circle):
        r = item.r + item.stroke_width / 2
        return (item.cx - r, item.cy - r, item.cx + r, item.cy + r)
    if isinstance(item, Line):
        h = item.width / 2
        return (min(item.x1, item.x2) - h, min(item.y1, item.y2) - h,
                max(item.x1, item.x2) + h, max(item.y1, item.y2) + h)
    return item.box()


def box_meets_circle(box, c: Circle) -> bool:
    dx = max(box[0] - c.cx, 0.0, c.cx - box[2])
    dy = max(box[1] - c.cy, 0.0, c.cy - box[3])
    return math.hypot(dx, dy) < c.r


def check_dots(dots: dict, config: PatternConfig, ids: Ids, origin) -> None:
    want = expected_dots(config, ids)
    assert set(dots) == set(want)
    for name, (x, y, r, fill) in want.items():
        got = dots[name]
        assert got[0] - origin[0] == pytest.approx(x, abs=0.01), name
        assert got[1] - origin[1] == pytest.approx(y, abs=0.01), name
        assert got[2] == pytest.approx(r, abs=0.01), name
        assert got[3] == fill, name


# Single sheet ---------------------------------------------------------------


def test_a3_svg_is_true_scale_and_dots_match_config():
    config = PatternConfig()
    sheets = layout_card(config, IDS, 'a3')
    assert len(sheets) == 1
    root = svg_root(svg_document(sheets[0]))
    assert root.get('width') == '297mm' and root.get('height') == '420mm'
    assert root.get('viewBox') == '0 0 297 420'
    dots = svg_dots(root)
    centre = dots['dot-centre'][:2]
    check_dots(dots, config, IDS, centre)
    # Point k at (k-1)*45 deg clockwise from up: y up on the card is smaller SVG y.
    for ring, radius in enumerate(config.ring_radii):
        for k in range(1, 9):
            x, y = dots[f'dot-r{ring}-p{k}'][:2]
            alpha = math.radians(45 * (k - 1))
            assert x - centre[0] == pytest.approx(1000 * radius * math.sin(alpha), abs=0.01)
            assert y - centre[1] == pytest.approx(-1000 * radius * math.cos(alpha), abs=0.01)
    top = min(dots.values(), key=lambda d: d[1])
    assert top == dots['dot-r0-p1'] and top[3] == '#000000'
    # Dots centred across the sheet, everything inside the printable area.
    assert centre[0] == pytest.approx(297 / 2)
    for x, y, r, _ in dots.values():
        assert MARGIN_MM <= x - r and x + r <= 297 - MARGIN_MM
        assert MARGIN_MM <= y - r and y + r <= 420 - MARGIN_MM
    assert sheets[0].origin_mm == pytest.approx(centre)


def test_label_scale_bar_and_up_mark():
    config = PatternConfig()
    sheet = layout_card(config, IDS, 'a3')[0]
    root = svg_root(svg_document(sheet))
    code = str(config.encode(2, 17, 3))
    label = by_id(root, 'label').text
    assert label == f'floor 2  room 17  card 3   code {code}'
    bar = by_id(root, 'scale-bar')
    x1, x2 = float(bar.get('x1')), float(bar.get('x2'))
    assert abs(x2 - x1) == pytest.approx(100.0, abs=1e-3)
    assert bar.get('y1') == bar.get('y2')
    ticks = sorted(float(e.get('x1')) for e in root.iter(SVG + 'line')
                   if e.get('class') == 'scale-tick')
    assert len(ticks) == 11
    assert np.diff(ticks) == pytest.approx([10.0] * 10, abs=1e-3)
    assert (ticks[0], ticks[-1]) == pytest.approx((min(x1, x2), max(x1, x2)), abs=1e-3)
    assert by_id(root, 'scale-text').text == '100 mm'

    dots = svg_dots(root)
    dot_bottom = max(y + r for _, y, r, _ in dots.values())
    for role in ('label', 'scale-bar', 'scale-tick', 'scale-text'):
        for item in sheet.with_role(role):
            assert item_box(item)[1] > dot_bottom, role      # below the pattern
    point1 = dots['dot-r0-p1']
    arrow = by_id(root, 'up-arrow')
    assert float(arrow.get('x1')) == pytest.approx(point1[0])
    assert max(float(arrow.get('y1')), float(arrow.get('y2'))) < point1[1] - point1[2]
    assert by_id(root, 'up-text').text == 'UP'


@pytest.mark.parametrize('paper', ['a3', 'tabloid', 'a4', 'letter'])
def test_notes_and_marks_never_touch_dots(paper):
    for config in (PatternConfig(), small_config(), big_config()):
        for sheet in layout_card(config, IDS, paper):
            dots = sheet.with_role('dot')
            notes = [item for item in sheet.items if item.role in NOTES]
            assert sheet.with_role('label') or sheet.tiled
            for item in notes:
                for dot in dots:
                    assert not box_meets_circle(item_box(item), dot), (item, dot.name)
            for edge in sheet.with_role('card-edge') + sheet.with_role('cut-line'):
                for dot in dots:
                    assert not box_meets_circle(item_box(edge), dot)


def test_card_wider_than_sheet_keeps_dots_and_draws_edges_that_fit():
    # The default card is 300 mm: wider than A3 (297 mm) and tabloid (279.4 mm).
    for paper in ('a3', 'tabloid'):
        sheet = layout_card(PatternConfig(), IDS, paper)[0]
        width, height = PAPER_SIZES_MM[paper]
        ox, oy = sheet.origin_mm
        assert ox == pytest.approx(width / 2)
        edges = sheet.with_role('card-edge')
        assert edges and all(e.y1 == e.y2 for e in edges)     # top and bottom only
        assert sorted({round(e.y1 - oy, 6) for e in edges}) == [-150.0, 150.0]
        for e in edges:
            assert MARGIN_MM - 1e-9 <= min(e.x1, e.x2) and max(e.x1, e.x2) <= width - MARGIN_MM
        check_dots({d.name: (d.cx, d.cy, d.r, '#{:02x}{:02x}{:02x}'.format(*d.fill))
                    for d in sheet.with_role('dot')}, PatternConfig(), IDS, sheet.origin_mm)


def test_non_default_config_is_honoured_and_fits_a4():
    config = small_config()
    sheets = layout_card(config, IDS, 'a4')
    assert len(sheets) == 1                   # 180 mm of dots fit an A4 sheet
    root = svg_root(svg_document(sheets[0]))
    assert root.get('viewBox') == '0 0 210 297'
    dots = svg_dots(root)
    check_dots(dots, config, IDS, dots['dot-centre'][:2])
    assert dots['dot-r0-p1'][3] == '#0a0a0a'
    # The whole 200 mm card fits: all four edges are drawn.
    assert len({(e.x1 == e.x2, round(e.x1 if e.x1 == e.x2 else e.y1, 6))
                for e in sheets[0].with_role('card-edge')}) == 4


def test_custom_paper_size():
    sheets = layout_card(PatternConfig(), IDS, '300x400')
    assert len(sheets) == 1 and (sheets[0].width_mm, sheets[0].height_mm) == (300, 400)


# Tiles ----------------------------------------------------------------------


def poster(value, origin):
    return (value[0] - origin[0], value[1] - origin[1])


@pytest.mark.parametrize('paper', ['a4', 'letter'])
def test_tiles_reassemble_the_card(paper):
    config = PatternConfig()
    sheets = layout_card(config, IDS, paper)
    assert len(sheets) == 2
    width, height = PAPER_SIZES_MM[paper]
    want = expected_dots(config, IDS)
    seen = {}
    windows = []
    for i, sheet in enumerate(sheets, start=1):
        assert {sheet.width_mm, sheet.height_mm} == {width, height}
        assert (sheet.tile, sheet.tiles) == (i, 2)
        root = svg_root(svg_document(sheet))
        assert root.get('width') == f'{sheet.width_mm:g}mm'
        assert by_id(root, 'tile-text').text.startswith(f'tile {i} of 2')
        x, y, w, h = sheet.window_mm
        o = sheet.origin_mm
        windows.append((x - o[0], y - o[1], x + w - o[0], y + h - o[1]))
        for name, (cx, cy, r, fill) in svg_dots(root).items():
            px, py = poster((cx, cy), o)
            assert (px, py, r, fill) == pytest.approx(want[name][:3] + (fill,), abs=0.01)
            assert fill == want[name][3]
            seen.setdefault(name, []).append(i)
    assert set(seen) == set(want)                   # the union is the whole pattern
    # Each dot lies wholly inside at least one tile (cut lines miss the dots).
    for name, (x, y, r, _) in want.items():
        assert any(w[0] <= x - r and x + r <= w[2] and w[1] <= y - r and y + r <= w[3]
                   for w in windows), name
    # Neighbouring windows overlap by OVERLAP_MM.
    a, b = windows
    overlap = max(min(a[2], b[2]) - max(a[0], b[0]), 0), max(min(a[3], b[3]) - max(a[1], b[1]), 0)
    assert sorted(overlap)[0] == pytest.approx(OVERLAP_MM)


def test_tiles_share_registration_marks_on_the_cut_line():
    sheets = layout_card(PatternConfig(), IDS, 'a4')
    marks = {}
    cuts = []
    for sheet in sheets:
        root = svg_root(svg_document(sheet))
        o = sheet.origin_mm
        for c in root.iter(SVG + 'circle'):
            if c.get('class') == 'registration':
                marks.setdefault(c.get('id'), []).append(
                    poster((float(c.get('cx')), float(c.get('cy'))), o))
        for line in sheet.with_role('cut-line'):
            cuts.append(poster((line.x1, line.y1), o) + poster((line.x2, line.y2), o))
        assert sheet.clip and root.find(f'{SVG}defs/{SVG}clipPath') is not None
    assert len(marks) >= 2
    for name, where in marks.items():
        assert len(where) == 2, name                      # printed on both tiles
        assert where[0] == pytest.approx(where[1], abs=1e-6)
    # All marks sit on the one cut line, which both tiles print at the same place.
    horizontal = all(c[1] == pytest.approx(c[3]) for c in cuts)
    axis = 1 if horizontal else 0
    line_at = {round(c[axis], 6) for c in cuts}
    assert len(line_at) == 1
    at = line_at.pop()
    assert all(where[0][axis] == pytest.approx(at) for where in marks.values())


def test_four_tiles_keep_the_scale_bar_whole_and_share_marks():
    config = big_config()
    sheets = layout_card(config, IDS, 'a4')
    assert len(sheets) == 4
    assert sorted((s.row, s.column) for s in sheets) == [(1, 1), (1, 2), (2, 1), (2, 2)]
    bars = []
    marks = {}
    seen = set()
    for sheet in sheets:
        x, y, w, h = sheet.window_mm
        seen |= {d.name for d in sheet.with_role('dot')}
        for bar in sheet.with_role('scale-bar'):
            inside = x <= min(bar.x1, bar.x2) and max(bar.x1, bar.x2) <= x + w
            crossed = any(min(bar.x1, bar.x2) < cut.x1 < max(bar.x1, bar.x2)
                          for cut in sheet.with_role('cut-line') if cut.x1 == cut.x2)
            bars.append((sheet.tile, inside and not crossed, bar.length))
        for mark in sheet.with_role('registration'):
            if isinstance(mark, Circle):
                marks.setdefault(mark.name, []).append(
                    (sheet.row, sheet.column) + poster((mark.cx, mark.cy), sheet.origin_mm))
    assert seen == set(expected_dots(config, IDS))
    assert [b[1:] for b in bars] == [(True, pytest.approx(100.0))]
    # Every seam (two vertical, two horizontal) has marks, each on its two tiles.
    pairs = set()
    for where in marks.values():
        assert len(where) == 2 and where[0][2:] == pytest.approx(where[1][2:])
        pairs.add((where[0][:2], where[1][:2]))
    assert pairs == {((1, 1), (1, 2)), ((2, 1), (2, 2)), ((1, 1), (2, 1)), ((1, 2), (2, 2))}


def test_tile_text_and_marks_in_pdf_and_png():
    sheets = layout_card(PatternConfig(), IDS, 'a4')
    pdf = pdf_document(sheets)
    assert b'(tile 1 of 2' in pdf and b'(tile 2 of 2' in pdf
    for sheet in sheets:
        img = png_image(sheet, 50)
        x, y, w, h = (int(round(v * 50 / 25.4)) for v in sheet.window_mm)
        # Clipped outside the window, something drawn inside it.
        assert (img[:y - 1] == 255).all() and (img[y + h + 1:] == 255).all()
        assert (img[y:y + h, x:x + w] < 128).any()


# PDF ------------------------------------------------------------------------


def pdf_objects(pdf: bytes) -> dict:
    """Parse the cross-reference table and check every offset; return obj number -> body."""
    start = int(re.search(rb'startxref\s+(\d+)\s+%%EOF\s*$', pdf).group(1))
    assert pdf[start:start + 4] == b'xref'
    lines = pdf[start:].split(b'\n')
    first, count = map(int, lines[1].split())
    assert first == 0
    entries = lines[2:2 + count]
    assert entries[0] == b'0000000000 65535 f '
    objects = {}
    for number, entry in enumerate(entries[1:], start=1):
        assert len(entry) == 19 and entry.endswith(b' n ')    # 20 bytes with '\n'
        offset = int(entry[:10])
        head = f'{number} 0 obj\n'.encode()
        assert pdf[offset:offset + len(head)] == head
        end = pdf.index(b'\nendobj', offset)
        objects[number] = pdf[offset + len(head):end]
    trailer = pdf[pdf.index(b'trailer', start):]
    assert int(re.search(rb'/Size (\d+)', trailer).group(1)) == count
    return objects


def pdf_pages(objects: dict):
    pages = []
    for body in objects.values():
        if b'/Type /Page ' in body or body.rstrip().endswith(b'/Type /Page'):
            box = [float(v) for v in re.search(rb'/MediaBox \[([^\]]*)\]', body).group(1).split()]
            content = int(re.search(rb'/Contents (\d+) 0 R', body).group(1))
            stream = objects[content]
            length = int(re.search(rb'/Length (\d+)', stream).group(1))
            data = stream[stream.index(b'stream\n') + 7:]
            assert data[length:] == b'endstream'
            pages.append((box, data[:length]))
    return pages


def pdf_filled_circles(content: bytes):
    """(cx, cy, r) of every filled 4-Bezier circle, in the content's mm units."""
    circles = []
    pattern = rb'(\S+) (\S+) m\n' + rb'(?:(\S+ ){5}\S+ c\n)' * 4 + rb'h\nf'
    for match in re.finditer(pattern, content):
        numbers = [float(v) for v in re.findall(rb'-?[\d.]+', match.group(0))]
        sx, sy = numbers[0], numbers[1]
        opposite = numbers[2 + 6 * 1 + 4:2 + 6 * 1 + 6]        # end of the second curve
        circles.append(((sx + opposite[0]) / 2, sy, (sx - opposite[0]) / 2))
    return circles


@pytest.mark.parametrize('paper,count', [('a3', 1), ('tabloid', 1), ('a4', 2), ('letter', 2)])
def test_pdf_structure_and_page_size(paper, count):
    sheets = layout_card(PatternConfig(), IDS, paper)
    pdf = pdf_document(sheets)
    assert pdf.startswith(b'%PDF-1.4\n')
    assert pdf.rstrip().endswith(b'%%EOF')
    objects = pdf_objects(pdf)
    assert re.search(rb'/Count (\d+)', pdf).group(1) == str(count).encode()
    pages = pdf_pages(objects)
    assert len(pages) == count
    width, height = PAPER_SIZES_MM[paper]
    for (box, _), sheet in zip(pages, sheets):
        assert box[:2] == [0, 0]
        assert sorted(box[2:]) == pytest.approx(sorted([width * 72 / 25.4, height * 72 / 25.4]),
                                                abs=1e-3)
        assert box[2:] == pytest.approx([sheet.width_mm * PT_PER_MM,
                                         sheet.height_mm * PT_PER_MM], abs=1e-3)
    assert b'/BaseFont /Helvetica' in pdf


def test_pdf_dots_match_svg_dots():
    config = small_config()
    sheet = layout_card(config, IDS, 'a3')[0]
    (box, content), = pdf_pages(pdf_objects(pdf_document([sheet])))
    assert b'0 0 -2.8346 0 1190.5512 cm' in content          # mm units, y down
    got = sorted(pdf_filled_circles(content))
    root = svg_root(svg_document(sheet))
    want = sorted((cx, cy, r) for cx, cy, r, _ in
                  list(svg_dots(root).values()) + list(svg_dots(root, 'mark').values()))
    assert len(got) == len(want) == 17 + 2          # the dots and the two handedness marks
    assert np.allclose(got, want, atol=1e-3)
    code = str(config.encode(2, 17, 3)).encode()
    assert b'(floor 2  room 17  card 3   code ' + code + b')' in content
    assert b'(100 mm)' in content


@pytest.mark.parametrize('config', [PatternConfig(), small_config()], ids=['shipped', 'small'])
def test_handedness_marks_are_printed_where_the_config_puts_them(config):
    sheet = layout_card(config, IDS, 'a3')[0]
    root = svg_root(svg_document(sheet))
    dots, marks = svg_dots(root), svg_dots(root, 'mark')
    centre = np.array(dots['dot-centre'][:2])
    # Poster y runs down: the pattern's (x, y) is printed at (x, -y) mm from the centre.
    want = config.mark_points() * 1000.0 * [1.0, -1.0]
    got = np.array([marks[f'mark-{k}'][:2] for k in (1, 2)]) - centre
    assert np.allclose(got, want, atol=1e-3)
    assert all(m[2] == pytest.approx(config.mark_radius * 1000.0) and m[3] == '#{:02x}{:02x}{:02x}'
               .format(*config.colour_rgb('K')) for m in marks.values())
    # Nothing is printed where a mirror would show the marks.
    mirrored = config.mark_points(mirrored=True) * 1000.0 * [1.0, -1.0] + centre
    for x, y in mirrored:
        for cx, cy, r, _ in list(dots.values()) + list(marks.values()):
            assert math.hypot(x - cx, y - cy) > r + config.mark_radius * 1000.0


def test_paper_cards_have_no_marks():
    sheet = layout_card(PatternConfig(handedness_mark=None), IDS, 'a3')[0]
    root = svg_root(svg_document(sheet))
    assert svg_dots(root, 'mark') == {} and len(svg_dots(root)) == 17


# PNG ------------------------------------------------------------------------


def png_chunks(data: bytes):
    assert data[:8] == b'\x89PNG\r\n\x1a\n'
    pos, chunks = 8, []
    while pos < len(data):
        length, kind = struct.unpack('>I4s', data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + length]
        crc, = struct.unpack('>I', data[pos + 8 + length:pos + 12 + length])
        assert crc == zlib.crc32(kind + body) & 0xFFFFFFFF
        chunks.append((kind, body))
        pos += 12 + length
    return chunks


def test_png_size_colours_and_subpixel_centre():
    config = PatternConfig()
    code = config.encode(2, 17, 3)
    sheet = layout_card(config, IDS, 'a3')[0]
    img = png_image(sheet, 100)
    scale = 100 / 25.4
    assert img.dtype == np.uint8
    assert img.shape == (round(420 * scale), round(297 * scale), 3)
    ox, oy = sheet.origin_mm
    centre_px = img[int(oy * scale), int(ox * scale)]
    assert tuple(centre_px[::-1]) == config.colour_rgb(code.centre)
    # Point 1 (black) and a white spot between the centre and point 1.
    p1 = img[int((oy - 113) * scale), int(ox * scale)]
    assert tuple(p1) == (0, 0, 0)
    assert tuple(img[int((oy - 40) * scale), int(ox * scale)]) == (255, 255, 255)
    # Anti-aliased edges put the centre dot where it belongs to a small fraction of a pixel.
    half = int(30 * scale)
    cx, cy = int(ox * scale), int(oy * scale)
    patch = img[cy - half:cy + half, cx - half:cx + half].astype(float)
    ink = 1.0 - patch.mean(axis=2) / 255.0              # the centre dot is black here
    ys, xs = np.mgrid[cy - half:cy + half, cx - half:cx + half] + 0.5
    assert (ink * xs).sum() / ink.sum() == pytest.approx(ox * scale, abs=0.02)
    assert (ink * ys).sum() / ink.sum() == pytest.approx(oy * scale, abs=0.02)
    assert ink.sum() == pytest.approx(math.pi * (24 * scale) ** 2, rel=0.003)
    assert ((ink > 0.02) & (ink < 0.98)).any()                 # edges are anti-aliased


def test_png_file_records_dpi(tmp_path):
    paths = write_card(tmp_path / 'card.png', PatternConfig(), IDS, 'a3', dpi=100)
    assert paths == [tmp_path / 'card.png']
    data = paths[0].read_bytes()
    chunks = png_chunks(data)
    kinds = [k for k, _ in chunks]
    assert kinds[0] == b'IHDR' and kinds.count(b'pHYs') == 1
    assert kinds.index(b'pHYs') < kinds.index(b'IDAT')
    x_ppm, y_ppm, unit = struct.unpack('>IIB', dict(chunks)[b'pHYs'])
    assert unit == 1 and x_ppm == y_ppm
    assert x_ppm * 0.0254 == pytest.approx(100, abs=0.01)
    img = cv2.imread(str(paths[0]))
    assert img.shape == (1654, 1169, 3)
    assert np.array_equal(img, png_image(layout_card(PatternConfig(), IDS, 'a3')[0], 100))


def test_png_bytes_replaces_an_existing_phys():
    once = png_bytes(np.full((4, 5, 3), 255, np.uint8), 300)
    img = cv2.imdecode(np.frombuffer(once, np.uint8), cv2.IMREAD_COLOR)
    assert img.shape == (4, 5, 3)
    assert [k for k, _ in png_chunks(once)].count(b'pHYs') == 1


# Files and errors -----------------------------------------------------------


def test_write_card_file_names(tmp_path):
    config = PatternConfig()
    svgs = write_card(tmp_path / 'card.svg', config, IDS, 'a4')
    assert svgs == [tmp_path / 'card-tile1.svg', tmp_path / 'card-tile2.svg']
    assert svgs == tile_paths(tmp_path / 'card.svg', 2)
    assert all(svg_dots(svg_root(p.read_text())) for p in svgs)
    pdfs = write_card(tmp_path / 'card.pdf', config, IDS, 'a4')
    assert pdfs == [tmp_path / 'card.pdf']
    assert len(pdf_pages(pdf_objects(pdfs[0].read_bytes()))) == 2
    one = write_card(tmp_path / 'one.SVG', config, IDS, 'a3')
    assert one == [tmp_path / 'one.SVG'] and one[0].read_text().startswith('<?xml')


def test_errors_are_package_errors(tmp_path):
    config = PatternConfig()
    with pytest.raises(ConfigError, match='unknown paper'):
        layout_card(config, IDS, 'a5')
    with pytest.raises(PrintError, match='unknown card format'):
        write_card(tmp_path / 'card.jpg', config, IDS)
    with pytest.raises(PrintError, match='cannot write'):
        write_card(tmp_path / 'missing' / 'card.svg', config, IDS)
    with pytest.raises(CodeError):
        layout_card(config, Ids(2, 500, 3))
    with pytest.raises(ConfigError, match='dpi'):
        write_card(tmp_path / 'card.png', config, IDS, dpi=0)
    with pytest.raises(ConfigError, match='dpi'):
        png_image(layout_card(config, IDS)[0], dpi=5000)
    huge = PatternConfig(card_size=2.6, ring_radii=(1.1, 0.7), ring_dot_radius=0.1,
                         centre_dot_radius=0.2)
    with pytest.raises(ConfigError, match='larger paper'):
        layout_card(huge, IDS, 'a4')
    assert issubclass(PrintError, PatternLocatorError)
    assert not list(tmp_path.iterdir())


def test_every_primitive_renders_in_every_format():
    items = (Rect(10, 10, 20, 5, (255, 0, 0), name='r', role='box'),
             Line(10, 30, 60, 30, 1.0, dash=(3, 2), role='dash'),
             Circle(40, 50, 8, stroke=(0, 0, 255), stroke_width=1.0, role='ring'),
             Text(30, 70, 'a (b) \\ c', 4, anchor='end', role='t'))
    sheet = CardSheet('a4', 100, 100, (0, 0), (0, 0, 100, 100), items, 'K-KRRRRRRR',
                      Ids(0, 1, 1))
    root = svg_root(svg_document(sheet))
    rect = by_id(root, 'r')
    assert (rect.get('width'), rect.get('height'), rect.get('fill')) == ('20', '5', '#ff0000')
    line = next(e for e in root.iter(SVG + 'line') if e.get('class') == 'dash')
    assert line.get('stroke-dasharray') == '3 2'
    ring = next(e for e in root.iter(SVG + 'circle') if e.get('class') == 'ring')
    assert ring.get('fill') == 'none' and ring.get('stroke') == '#0000ff'
    (_, content), = pdf_pages(pdf_objects(pdf_document([sheet])))
    assert b'10 10 20 5 re f' in content and b'[3 2] 0 d' in content
    assert b'(a \\(b\\) \\\\ c) Tj' in content
    img = png_image(sheet, 254)                       # 10 px per mm
    assert tuple(img[120, 200]) == (0, 0, 255)         # inside the red rectangle (BGR)
    assert tuple(img[95, 200]) == (255, 255, 255)     # just above it
    assert img[300, 101].max() < 100 and tuple(img[300, 135]) == (255, 255, 255)  # dash, gap
    assert tuple(img[500, 480]) == (255, 0, 0)        # on the blue ring
    assert tuple(img[500, 400]) == (255, 255, 255)    # its inside stays white
    assert (img[640:700, 150:300] < 128).any()         # the text, left of x = 30 mm


def test_text_primitive_box_follows_anchor():
    left = Text(10, 20, 'floor 2', 4).box()
    middle = Text(10, 20, 'floor 2', 4, anchor='middle').box()
    assert left[0] == 10 and middle[0] == pytest.approx(10 - (left[2] - left[0]) / 2)
    assert left[1] < 20 < left[3]
