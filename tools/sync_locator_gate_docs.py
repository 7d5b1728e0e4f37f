"""
Write the locator's parameter groups into docs/ros.md and config/locator.yaml.

The groups ``gates.*``, ``uncertainty.*`` and ``gaze.*`` are declared from
the cores' dataclasses (``GateParameters``, ``UncertaintyParameters``,
``GazeParameters``; ``locator_node.PARAMETER_GROUPS``); this keeps the two
hand-read files in step with them (test_ros_doc and test_system check that
they are). A group's rows (lines) are replaced where they stand; a group
not there yet goes right after the group before it. Run from the
repository root:

    .venv/bin/python tools/sync_locator_gate_docs.py
"""

from pathlib import Path
import re

from pattern_locator.nodes.locator_node import PARAMETER_GROUPS, PARAMETERS


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


def _replace(text: str, prefix: str, previous: str, block: str, pattern: str, where: str
             ) -> str:
    """Replace the lines of group ``prefix`` with ``block`` (after ``previous``'s if absent)."""
    lines = pattern.format(re.escape(prefix + '.'))
    text, n = re.subn(lines, lambda m: block, text, count=1)
    if n == 1:
        return text
    before = pattern.format(re.escape(previous + '.'))
    text, n = re.subn(before, lambda m: m.group(0) + block, text, count=1)
    assert n == 1, f'{where} has neither {prefix} nor {previous} lines'
    return text


def main() -> None:
    doc = Path('docs/ros.md')
    config = Path('config/locator.yaml')
    doc_text, config_text = doc.read_text(), config.read_text()
    previous = None
    for prefix, _, _ in PARAMETER_GROUPS:
        group = [p for p in PARAMETERS if p.name.startswith(prefix + '.')]
        rows = '\n'.join(_doc_row(p) for p in group) + '\n'
        lines = '\n'.join(_yaml_line(p) for p in group) + '\n'
        doc_text = _replace(doc_text, prefix, previous, rows, r'(\| `{}[^\n]*\n)+',
                            'docs/ros.md')
        config_text = _replace(config_text, prefix, previous, lines, r'(    {}[^\n]*\n)+',
                               'config/locator.yaml')
        previous = prefix
    doc.write_text(doc_text)
    config.write_text(config_text)


if __name__ == '__main__':
    main()
