"""
Where the package's shipped files (config/) are found.

In a source checkout (or an editable install) they sit beside the package;
after ``colcon build`` they live in the package's share directory on the
ament index. Both are tried, in that order, so an edited source file wins.
"""

from pathlib import Path

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
