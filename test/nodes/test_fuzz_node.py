"""
Malformed messages into a real locator process over DDS (a short ``bench --fuzz``).

Broken Image, CameraInfo and JointState messages, interleaved with good ones
and two bursts of 2000x2000 noise frames and oversized frames: the node must
publish no pose for any of them and nothing non-finite, log little and in
short lines, give big buffers back, stay alive, and still locate a good
image at the end. Both *structural* garbage (what the node itself must
refuse) and *implausible* but well-formed values (intrinsics, joint angles
far outside the head's travel: the validators' job) are sent;
``pattern-locator bench --fuzz`` sends many more.
"""

from pattern_locator.evaluation.fuzz import run_fuzz, STRUCTURAL


def test_malformed_messages_give_no_pose_and_the_node_lives_on(tmp_path):
    summary = run_fuzz(messages=2400, seed=5, bursts=2, burst_frames=6, implausible=True,
                       log_dir=tmp_path, progress=print)
    print(summary.line())
    assert len(set(summary.slots_by_category) & STRUCTURAL) >= 15, summary.slots_by_category
    assert set(summary.slots_by_category) - STRUCTURAL, 'no implausible input was sent'
    assert summary.poses_for_bad == {}, summary.poses_for_bad
    assert summary.non_finite == 0
    assert summary.tracebacks == 0
    assert summary.alive and summary.final_good_located
    assert summary.good_located >= 0.9 * summary.good_sent, summary.line()
    # Oversized frames were refused before they were read.
    assert int(summary.node_counts['refused_oversize']) >= 1
    # Bounded log: at most 100 KB per minute of garbage, no line longer than
    # a few hundred characters however long the foreign strings were.
    assert summary.log_bytes_per_min <= 100 * 1024, summary.line()
    lines = (tmp_path / 'locator_fuzz.log').read_text(errors='replace').splitlines()
    assert max(len(line) for line in lines) < 700
    # Bounded memory: back within 50 MB of the warm baseline once idle.
    assert summary.rss_after_mb - summary.rss_baseline_mb <= 50.0, summary.line()
