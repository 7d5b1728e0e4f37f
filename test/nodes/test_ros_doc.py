"""docs/ros.md documents every parameter of every node, as declared; the problem log."""

import importlib
from pathlib import Path
import re

import pytest

DOC = Path(__file__).resolve().parents[2] / 'docs' / 'ros.md'


@pytest.mark.parametrize('module', ['locator_node', 'camera_driver_node', 'sim_node'])
def test_every_parameter_is_in_the_doc_as_declared(module):
    text = DOC.read_text()
    node = module.replace('_node', '')
    section = text.split(f'### {node} parameters', 1)[1].split('\n#', 1)[0]
    rows = {m[1]: m[2] for m in re.finditer(r'^\| `([^`]+)` \|.*\| (dynamic|read-only) \|',
                                            section, re.MULTILINE)}
    declared = importlib.import_module(f'pattern_locator.nodes.{module}').PARAMETERS
    assert rows == {p.name: 'dynamic' if p.dynamic else 'read-only' for p in declared}


def test_problems_are_throttled_by_kind_and_cut():
    """ProblemLog: one line per kind and period, however varied the text; counts bounded."""
    from pattern_locator.nodes.ros_helpers import MAX_KINDS, ProblemLog

    class Logger:

        def __init__(self):
            self.lines = []

        def warning(self, text):
            self.lines.append(text)

    logger = Logger()
    log = ProblemLog(logger, period_s=3600.0)
    for i in range(1000):
        log.report('image', f"unsupported image encoding '{'x' * i}\n{i}'")
    for i in range(200):
        log.report(f'rejected: reason {i}', 'text')
    counts, last = log.snapshot()
    assert counts['image'] == 1000
    assert len(counts) == MAX_KINDS and counts['other'] == 200 - (MAX_KINDS - 2)
    assert len([line for line in logger.lines if 'encoding' in line]) == 1
    assert all(len(line) < 300 and '\n' not in line for line in logger.lines)
    assert '\n' not in last
    # Once the period is over, a line says how many of its kind it left out,
    # the kind quoted: a kind is the leading words of a rejection.
    log = ProblemLog(logger, period_s=0.0)
    log.report('rejected: position uncertain by', 'card K-KRGBGRBB: position uncertain by 1 m')
    log.period_s = 3600.0
    for _ in range(3):
        log.report('rejected: position uncertain by', 'card K-KRGBGRBB: position uncertain')
    log.period_s = 0.0
    log.report('rejected: position uncertain by', 'card K-KRGBGRBB: position uncertain by 2 m')
    assert logger.lines[-1].endswith(
        "(3 more 'rejected: position uncertain by' problems since the last report)")


def test_the_start_up_log_is_short_lines_with_every_parameter():
    """describe_values: every parameter named, no line longer than its width, long values cut."""
    from pattern_locator.nodes.locator_node import PARAMETERS
    from pattern_locator.nodes.ros_helpers import describe_values

    values = {p.name: p.default for p in PARAMETERS}
    values['building_map'] = '/very/long/path/' * 60
    lines = describe_values(values, width=300)
    assert len(lines) > 1 and all(len(line) <= 300 for line in lines)
    text = ', '.join(lines)
    assert all(f'{name}=' in text for name in values)
    assert 'building_map=/very/long/path/' in text and '...' in text
    assert describe_values({}) == ['']
