"""
Write the locator's ``gates.*`` parameters into docs/ros.md and config/locator.yaml.

The gates' thresholds are declared from ``localization.gates.GateParameters``;
this keeps the two hand-read files in step with it (test_ros_doc and
test_system check that they are). Run from the repository root:

    .venv/bin/python tools/sync_locator_gate_docs.py
"""

from pathlib import Path
import re

from pattern_locator.nodes.locator_node import PARAMETERS


def _doc_row(p) -> str:
    kind = ('bool' if isinstance(p.default, bool) else 'integer' if isinstance(p.default, int)
            else 'double' if isinstance(p.default, float) else 'string')
    default = (f'`{str(p.default).lower()}`' if isinstance(p.default, bool)
               else f"`'{p.default}'`" if isinstance(p.default, str) else f'`{p.default}`')
    span = (' \\| '.join(p.choices) if p.choices
            else f'{p.low:g} .. {p.high:g}' if p.low is not None else '')
    return (f'| `{p.name}` | {kind} | {default} | {span} | '
            f"{'dynamic' if p.dynamic else 'read-only'} | {p.description} |")


def _yaml_line(p) -> str:
    value = str(p.default).lower() if isinstance(p.default, bool) else p.default
    return f'    {p.name}: {value}'


def main() -> None:
    gates = [p for p in PARAMETERS if p.name.startswith('gates.')]
    doc = Path('docs/ros.md')
    text = doc.read_text()
    rows = '\n'.join(_doc_row(p) for p in gates) + '\n'
    text, n = re.subn(r'(\| `gates\.[^\n]*\n)+', lambda m: rows, text, count=1)
    assert n == 1, 'docs/ros.md has no gates rows to replace'
    doc.write_text(text)
    config = Path('config/locator.yaml')
    text = config.read_text()
    lines = '\n'.join(_yaml_line(p) for p in gates) + '\n'
    text, n = re.subn(r'(    gates\.[^\n]*\n)+', lambda m: lines, text, count=1)
    assert n == 1, 'config/locator.yaml has no gates lines to replace'
    config.write_text(text)


if __name__ == '__main__':
    main()
