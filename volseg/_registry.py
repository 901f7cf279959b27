"""A table of named choices (a leaf): operators, cut measures, fields.

Every list of choices (the command line's, a pipeline's, a figure's legend, the
parametrised tests) reads its table, and code asks an entry for what it needs
(``entry.pruned``), never compares names. Adding a choice is adding an entry.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping

__all__ = ["Registry"]


class Registry(Mapping):
    """Entries (frozen dataclasses with a ``name`` and ``aliases``) by name.

    `option` names the argument in errors: ``get`` of an unknown name raises
    ``ValueError("unknown `measure` 'x'; choose one of ...")``. Lookups are
    case-insensitive and accept hyphens for underscores.
    """

    def __init__(self, option: str, entries) -> None:
        self.option = option
        self._entries = {entry.name: entry for entry in entries}
        self._by_alias = {}
        for entry in self._entries.values():
            for alias in (entry.name, *getattr(entry, "aliases", ())):
                self._by_alias[alias.lower()] = entry
                self._by_alias[alias.lower().replace("_", "-")] = entry

    def get(self, name, default=None):  # noqa: D102 (Mapping's)
        if isinstance(name, str):
            return self._by_alias.get(name.lower(), default)
        return name if name in self._entries.values() else default

    def __getitem__(self, name):
        entry = self.get(name)
        if entry is None:
            raise ValueError(f"unknown `{self.option}` {name!r}; choose one of "
                             + ", ".join(repr(n) for n in self._entries))
        return entry

    def __iter__(self) -> Iterator[str]:
        return iter(self._entries)

    def __len__(self) -> int:
        return len(self._entries)

    def choices(self) -> list[str]:
        """What a command line accepts: the names, hyphenated, then the aliases."""
        shown = [name.replace("_", "-") for name in self._entries]
        return list(dict.fromkeys([*shown, *self._entries, *self._by_alias]))
