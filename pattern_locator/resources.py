"""
Where the package's shipped files (config/) are found, and how YAML files are read.

In a source checkout (or an editable install) they sit beside the package;
after ``colcon build`` they live in the package's share directory on the
ament index. Both are tried, in that order, so an edited source file wins.

Every YAML file goes through :func:`read_yaml`, which bounds what a file can
cost: regular files only (a FIFO or a device would block or never end), a
size limit, a nesting-depth limit (deep nesting overflows PyYAML's
recursion) and an alias limit (aliases that refer to aliases expand
exponentially: the "billion laughs").
"""

import os
from pathlib import Path
import stat
from typing import Any, Dict, Tuple, Type, Union

import yaml

from .errors import ConfigError, PatternLocatorError

PACKAGE = 'pattern_locator'
SOURCE_ROOT = Path(__file__).resolve().parent.parent

# Defaults, for small files (pattern, camera, zoom table: each under 3 KB and
# 300 values). PyYAML reads ~20k values a second, so these bound the time too;
# the building map's loader passes larger limits.
MAX_YAML_BYTES = 256 * 1024
MAX_YAML_NODES = 20_000               # values (scalars and collections), aliases expanded
MAX_YAML_DEPTH = 64                   # nesting of collections; the shipped files need 8
MAX_YAML_ALIASES = 100                # alias uses per file
QUOTE_CHARS = 80                      # foreign text in a message is cut to this


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


def quote(text: Any, limit: int = QUOTE_CHARS) -> str:
    """Return ``repr`` of foreign text cut to ``limit`` characters, for one-line messages."""
    shown = repr(text if isinstance(text, str) else str(text))
    return shown if len(shown) <= limit else shown[:limit - 3] + '...'


def open_regular_file(path: Union[str, Path], what: str,
                      error: Type[PatternLocatorError] = ConfigError
                      ) -> Tuple[int, os.stat_result]:
    """
    Open a regular file read-only; return its descriptor (the caller closes it) and stat.

    Opened without blocking and checked with ``fstat`` on the open file, so a
    FIFO, a socket, a device or a directory is refused at once (and a file
    swapped for one after a check cannot block either): ``error`` in one line.
    """
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, 'O_CLOEXEC', 0))
    except OSError as exc:
        raise error(f'{path}: cannot read {what} ({exc.strerror or exc})') from None
    try:
        info = os.fstat(fd)
        if stat.S_ISDIR(info.st_mode):
            raise error(f'{path}: cannot read {what} (is a directory)')
        if not stat.S_ISREG(info.st_mode):
            kind = 'a FIFO' if stat.S_ISFIFO(info.st_mode) else 'not a regular file'
            raise error(f'{path}: cannot read {what} (is {kind})')
    except BaseException:
        os.close(fd)
        raise
    return fd, info


def read_file_bytes(path: Union[str, Path], what: str, max_bytes: int,
                    error: Type[PatternLocatorError] = ConfigError) -> bytes:
    """
    Return a regular file's bytes, at most ``max_bytes``; ``error`` in one line if not.

    The file is opened as :func:`open_regular_file` does.
    """
    fd, info = open_regular_file(path, what, error)
    try:
        if info.st_size > max_bytes:
            raise error(f'{path}: {what} is too large ({info.st_size} bytes; the limit is '
                        f'{max_bytes})')
        chunks, total = [], 0
        while total <= max_bytes:          # the file may grow after fstat
            chunk = os.read(fd, min(1 << 20, max_bytes + 1 - total))
            if not chunk:
                break
            chunks.append(chunk)
            total += len(chunk)
        if total > max_bytes:
            raise error(f'{path}: {what} is too large (more than {max_bytes} bytes)')
        return b''.join(chunks)
    except OSError as exc:
        raise error(f'{path}: cannot read {what} ({exc.strerror or exc})') from None
    finally:
        os.close(fd)


class YamlLimitError(yaml.MarkedYAMLError):
    """A YAML file goes beyond a limit of :func:`read_yaml` (depth, aliases, expansion)."""

    def __init__(self, problem: str, mark: Any) -> None:
        super().__init__(problem=problem, problem_mark=mark)


class _Limited:
    """
    Mixed into a loader class: count nesting depth, aliases and nodes.

    ``compose_node`` is where PyYAML recurses and resolves aliases, so the
    limits stop a bad file while it is composed, before anything is built.
    Each node's size (itself plus its children, aliases expanded) is kept,
    so an alias costs the size of what it refers to; the running total
    stops a long file early too (PyYAML takes ~50 us a node).
    """

    max_nodes = MAX_YAML_NODES

    def compose_node(self, parent: Any, index: Any) -> Any:
        if not hasattr(self, '_sizes'):
            self._depth, self._aliases, self._total = 0, 0, 0
            self._sizes: Dict[int, int] = {}
        if self.check_event(yaml.AliasEvent):
            self._aliases += 1
            event = self.peek_event()
            if self._aliases > MAX_YAML_ALIASES:
                raise YamlLimitError(f'more than {MAX_YAML_ALIASES} aliases', event.start_mark)
            target = self.anchors.get(event.anchor)
            if target is not None:
                if id(target) not in self._sizes:
                    raise YamlLimitError(f'alias *{event.anchor[:QUOTE_CHARS]} refers to a '
                                         f'collection that contains it', event.start_mark)
                self._count(self._sizes[id(target)], event.start_mark)
            return super().compose_node(parent, index)
        self._count(1, self.peek_event().start_mark)
        self._depth += 1
        try:
            if self._depth > MAX_YAML_DEPTH:
                raise YamlLimitError(f'nested deeper than {MAX_YAML_DEPTH} levels',
                                     self.peek_event().start_mark)
            node = super().compose_node(parent, index)
        finally:
            self._depth -= 1
        if isinstance(node, yaml.MappingNode):
            children = [n for pair in node.value for n in pair]
        elif isinstance(node, yaml.SequenceNode):
            children = node.value
        else:
            children = ()
        self._sizes[id(node)] = 1 + sum(self._sizes.get(id(child), 1) for child in children)
        return node

    def _count(self, nodes: int, mark: Any) -> None:
        self._total += nodes
        if self._total > self.max_nodes:
            raise YamlLimitError(f'more than {self.max_nodes} values (counting what aliases '
                                 f'repeat)', mark)


_limited_loaders: Dict[type, type] = {}


def limited_loader(loader: Type[yaml.SafeLoader]) -> type:
    """Return ``loader`` with :func:`read_yaml`'s depth, alias and expansion limits."""
    if loader not in _limited_loaders:
        _limited_loaders[loader] = type(f'Limited{loader.__name__}', (_Limited, loader), {})
    return _limited_loaders[loader]


class UniqueKeyLoader(yaml.SafeLoader):
    """A safe loader that refuses a key given twice in one mapping (PyYAML keeps the last)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict:
        seen = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            try:
                duplicate = key in seen
                seen.add(key)
            except TypeError:
                continue            # unhashable key: the base class reports it
            if duplicate:
                raise yaml.constructor.ConstructorError(
                    None, None, f'duplicate key {quote(key)}', key_node.start_mark)
        return super().construct_mapping(node, deep)


def read_yaml(path: Union[str, Path], what: str,
              error: Type[PatternLocatorError] = ConfigError,
              loader: Type[yaml.SafeLoader] = yaml.SafeLoader,
              max_bytes: int = MAX_YAML_BYTES, max_nodes: int = MAX_YAML_NODES) -> Any:
    """
    Return a YAML file's data; ``error`` in one line naming the file if it cannot be.

    ``what`` names the file in the messages (``the building map``). Refused:
    anything but a regular file, more than ``max_bytes``, nesting deeper
    than ``MAX_YAML_DEPTH``, more than ``MAX_YAML_ALIASES`` aliases, more
    than ``max_nodes`` values (scalars and collections, counting each alias
    as what it repeats), text that is not UTF-8, malformed YAML.
    ``loader``: a ``yaml.SafeLoader`` subclass (e.g. :class:`UniqueKeyLoader`);
    the limits are added to it.
    """
    data = read_file_bytes(path, what, max_bytes, error)
    try:
        text = data.decode('utf-8')
    except UnicodeDecodeError:
        raise error(f'{path}: {what} is not UTF-8 text') from None
    instance = None
    try:
        instance = limited_loader(loader)(text)       # the reader checks the characters
        instance.max_nodes = max_nodes
        return instance.get_single_data()
    except YamlLimitError as exc:
        mark = exc.problem_mark
        where = f' at line {mark.line + 1}' if mark is not None else ''
        raise error(f'{path}: {what} refused{where}: {exc.problem}') from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        where = f' at line {mark.line + 1}' if mark is not None else ''
        problem = getattr(exc, 'problem', None)
        raise error(f'{path}: malformed YAML{where}'
                    + (f': {problem[:2 * QUOTE_CHARS]}' if problem else '')) from None
    except (ValueError, OverflowError) as exc:
        # A value PyYAML's constructors cannot build: an integer of more than
        # 4300 digits, a date such as 2024-13-45.
        raise error(f'{path}: malformed YAML: a value cannot be read '
                    f'({str(exc)[:QUOTE_CHARS]})') from None
    finally:
        if instance is not None:
            instance.dispose()
