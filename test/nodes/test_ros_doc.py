"""docs/ros.md documents every parameter of every node, as declared."""

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
