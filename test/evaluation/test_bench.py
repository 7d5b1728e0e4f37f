"""The benchmark's machinery on a handful of scenes (accuracy only; nothing is timed)."""

import math

import numpy as np
from pattern_locator.card.pattern import load_pattern_config
from pattern_locator.evaluation import bench
import pytest


@pytest.fixture(scope='module')
def results():
    config = load_pattern_config()
    scenes = bench.make_scenes(config, 1, seed=5)
    return scenes, bench.run_scenes(scenes, config, progress=False)


def test_scenes_cover_both_cameras_and_every_distance_bin(results):
    scenes, _ = results
    assert {s.camera_name for s in scenes} == set(bench.bench_cameras())
    for s in scenes:
        near, far = bench.DISTANCE_BINS[s.bin_index]
        assert near <= s.distance <= far and 0.0 <= s.view_angle <= 70.0


def test_every_marker_ran_on_every_scene(results):
    scenes, res = results
    for marker in bench.MARKERS:
        assert len(res[marker]) == len(scenes)
        assert all(not math.isnan(o.time_ms) for _, o in res[marker])


def test_dot_cards_are_found_near_and_never_misread(results):
    _, res = results
    near = [o for s, o in res['dots'] if s.bin_index <= 2]
    assert all(o.found for o in near)
    assert sum(o.wrong_ids for _, o in res['dots']) == 0
    for s, o in res['dots']:
        if o.found:
            # Within 2 % of the distance, and the bound machinery produced samples.
            assert o.position_error < 0.02 * s.distance
            assert o.crb_samples is not None and np.all(np.isfinite(o.crb_samples))


def test_tables_name_every_bin_and_marker(results):
    _, res = results
    text = '\n'.join(bench.accuracy_table(res, name) for name in bench.bench_cameras())
    for near, far in bench.DISTANCE_BINS:
        assert f'{near:g}-{far:g}' in text
    for marker in bench.MARKERS:
        assert marker in text
    assert 'Planar flips' in bench.flip_table(res)


def test_time_and_quick_tables_have_their_columns(results):
    _, res = results
    text = bench.time_table(res)
    assert 'median' in text and 'p99' in text and 'max' in text and 'both cameras' in text
    quick = bench.quick_table(res).splitlines()
    assert len(quick) == 1 + 2 * len(bench.MARKERS)         # far fewer than the full tables
    assert bench.time_stats([1.0, 2.0, 3.0, float('nan')]) == pytest.approx(
        (2.0, 2.0, 2.98, 3.0))


def test_plots_of_each_run_kind_have_their_own_files(results, tmp_path):
    _, res = results
    bench._plots(res, str(tmp_path), 'bench')
    bench._plots(res, str(tmp_path), 'bench_quick')
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ['bench_errors.png', 'bench_quick_errors.png', 'bench_quick_times.png',
                     'bench_times.png']
    assert all(p.stat().st_size > 10_000 for p in tmp_path.iterdir())


def test_node_bench_tail_table_gives_every_series_its_tail():
    from pattern_locator.evaluation.bench_node import tail_table
    times = [float(v) for v in range(1, 101)]
    text = tail_table({'640x480': {
        'tight': times, 'paced': [2 * t for t in times], 'latency': [],
        'node': {'in_node_ms_median': '3.25', 'in_node_ms_p95': '4.50',
                 'in_node_ms_max': '9.75', 'in_node_ms_mean': 'not reported'}}})
    rows = {line[:26].strip(): line[26:].split() for line in text.splitlines()[1:]}
    assert rows['640x480 core tight'] == ['50.50', '50.50', '95.05', '99.01', '100.00']
    assert rows['640x480 core paced'][-1] == '200.00'
    # The node keeps median, p95 and max only; no mean or p99 is made up.
    assert rows['640x480 in the node'] == ['3.25', '-', '4.50', '-', '9.75']
    # No pose came back: nothing to report, and no error.
    assert rows['640x480 latency'] == ['-'] * 5
