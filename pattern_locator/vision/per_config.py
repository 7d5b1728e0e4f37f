"""Values made once per pattern configuration, found again by the configuration's identity."""

from typing import Callable, Dict, Tuple, TypeVar

from ..card.pattern import PatternConfig

T = TypeVar('T')

# Configurations kept per table: a process uses one or two.
_MOST = 16


def made_once(table: Dict[int, Tuple[PatternConfig, T]], config: PatternConfig,
              make: Callable[[PatternConfig], T]) -> T:
    """
    Return ``make(config)``, made at the first call for ``config`` and kept in ``table``.

    Keyed by identity: hashing a configuration (a frozen dataclass of
    tuples) costs more than the work most of these save. The configuration
    is kept beside its value, so that another object given the same id
    later is not taken for it; a table holds at most 16.
    """
    entry = table.get(id(config))
    if entry is None or entry[0] is not config:
        if len(table) >= _MOST:
            table.clear()
        entry = table[id(config)] = (config, make(config))
    return entry[1]
