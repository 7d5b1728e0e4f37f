"""
The layout's rules, checked on the source.

* Only ``nodes/`` and ``evaluation/`` import ROS (rclpy or message packages).
* Nothing imports ``evaluation/`` except ``cli.py``.
* Importing every core module in a fresh interpreter loads no ROS module.
"""

import ast
from pathlib import Path
import subprocess
import sys

PACKAGE = Path(__file__).resolve().parents[1] / 'pattern_locator'
ROS_ROOTS = {'rclpy', 'rosidl_runtime_py', 'sensor_msgs', 'geometry_msgs', 'std_msgs',
             'diagnostic_msgs', 'nav_msgs', 'std_srvs', 'rcl_interfaces', 'builtin_interfaces',
             'launch', 'launch_ros', 'rosgraph_msgs', 'tf2_msgs'}
ROS_ALLOWED = {'nodes', 'evaluation'}
SUBPACKAGES = ['card', 'vision', 'localization', 'visca', 'tracking', 'sim', 'survey', 'nodes',
               'evaluation']


def _modules():
    for path in sorted(PACKAGE.rglob('*.py')):
        parts = path.relative_to(PACKAGE.parent).with_suffix('').parts
        yield path, parts


def _imports(path: Path, parts) -> set:
    """Absolute names of everything ``path`` imports (relative imports resolved)."""
    tree = ast.parse(path.read_text(), str(path))
    package = list(parts[:-1])
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[:len(package) - node.level + 1]
                module = '.'.join(base + ([node.module] if node.module else []))
                if node.module is None:
                    names.update(f'{module}.{alias.name}' for alias in node.names)
                else:
                    names.add(module)
            else:
                names.add(node.module)
    return names


def test_every_module_lives_in_a_subpackage_or_is_one_of_the_top_three():
    top = sorted(p.name for p in PACKAGE.glob('*.py'))
    assert top == ['__init__.py', 'cli.py', 'errors.py', 'resources.py']
    for path, parts in _modules():
        if len(parts) == 3:
            assert parts[1] in SUBPACKAGES, path


def test_only_nodes_and_evaluation_import_ros():
    offenders = []
    for path, parts in _modules():
        sub = parts[1] if len(parts) == 3 else None
        if sub in ROS_ALLOWED:
            continue
        ros = sorted(n for n in _imports(path, parts) if n.split('.')[0] in ROS_ROOTS)
        if ros:
            offenders.append(f'{path.relative_to(PACKAGE.parent)}: {ros}')
    assert offenders == []


def test_nothing_but_cli_imports_evaluation():
    offenders = []
    for path, parts in _modules():
        if parts[1] == 'evaluation' or parts == ('pattern_locator', 'cli'):
            continue
        bad = sorted(n for n in _imports(path, parts)
                     if n.startswith('pattern_locator.evaluation'))
        if bad:
            offenders.append(f'{path.relative_to(PACKAGE.parent)}: {bad}')
    assert offenders == []


def test_the_import_reader_sees_relative_and_absolute_imports(tmp_path):
    # The rules are only as good as the reader: it must resolve both forms.
    module = tmp_path / 'detector.py'
    module.write_text('import rclpy.node\n'
                      'from sensor_msgs.msg import Image\n'
                      'from ..evaluation.bench import run_bench\n'
                      'from . import camera\n')
    names = _imports(module, ('pattern_locator', 'vision', 'detector'))
    assert {'rclpy.node', 'sensor_msgs.msg', 'pattern_locator.evaluation.bench',
            'pattern_locator.vision.camera'} <= names


def test_core_modules_do_not_load_ros_when_imported():
    core = ['.'.join(parts) for _, parts in _modules()
            if len(parts) == 3 and parts[1] not in ROS_ALLOWED and parts[2] != '__init__']
    core.append('pattern_locator.cli')
    code = ('import sys\n'
            + ''.join(f'import {name}\n' for name in core)
            + 'bad = sorted(m for m in sys.modules if m.split(".")[0] in '
              f'{sorted(ROS_ROOTS)!r})\n'
              'print(",".join(bad))\n')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == ''


def test_every_module_is_named_in_the_design_layout():
    # docs/design.md's layout table is how a reader finds a module: keep it whole.
    design = (PACKAGE.parent / 'docs' / 'design.md').read_text()
    missing = [str(path.relative_to(PACKAGE)) for path in sorted(PACKAGE.glob('*/*.py'))
               if path.name != '__init__.py' and f'`{path.name}`' not in design]
    assert not missing, f'modules missing from docs/design.md: {missing}'
