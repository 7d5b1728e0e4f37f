"""
Where the package's shipped files (config/) are found, and how YAML files are read.

In a source checkout (or an editable install) they sit beside the package;
after ``colcon build`` they live in the package's share directory on the
ament index. Both are tried, in that order, so an edited source file wins.
"""

from pathlib import Path
from typing import Any, Type, Union

import yaml

from .errors import ConfigError, PatternLocatorError

PACKAGE = 'pattern_locator'
SOURCE_ROOT = Path(__file__).resolve().parent.parent


def config_path(name: str) -> Path:
    """Path of a shipped configuration file such as ``pattern.yaml``."""
    source = SOURCE_ROOT / 'config' / name
    if source.is_file():
        return source
    try:
        from ament_index_python.packages import get_package_share_directory
        installed = Path(get_package_share_directory(PACKAGE)) / 'config' / name
    except (ImportError, LookupError, OSError, ValueError):
        return source
    return installed if installed.is_file() else source


def read_yaml(path: Union[str, Path], what: str,
              error: Type[PatternLocatorError] = ConfigError,
              loader: Type[yaml.SafeLoader] = yaml.SafeLoader) -> Any:
    """
    Return a YAML file's data; ``error`` in one line naming the file if it cannot be.

    ``what`` names the file in the messages (``the building map``).
    """
    try:
        with open(path, encoding='utf-8') as stream:
            return yaml.load(stream, Loader=loader)
    except OSError as exc:
        raise error(f'{path}: cannot read {what} ({exc.strerror or exc})') from None
    except UnicodeDecodeError:
        raise error(f'{path}: {what} is not UTF-8 text') from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        where = f' at line {mark.line + 1}' if mark is not None else ''
        problem = getattr(exc, 'problem', None)
        raise error(f'{path}: malformed YAML{where}' + (f': {problem}' if problem else '')
                    ) from None
