"""Registries: one name -> entry table per extension point (builders, ray patterns, drop, noise and intensity models, writers, commands).

Each extension module registers its entry (the function and the dataclass of its config section)
with one line; the pipeline looks entries up by the name the config gives and never names a
concrete one. A registry is the one list of its names: validation messages, the panel's menus and
the docs read them from here.
"""

from __future__ import annotations

from typing import Generic, Iterator, TypeVar

from .errors import InputError

T = TypeVar("T")


class Registry(Generic[T]):
    """Named entries of one kind.

    kind : what an entry is, for messages ("scene builder")
    key : the config key that names an entry ("scene.builder"), the default ``where`` of errors
    """

    def __init__(self, kind: str, key: str):
        self.kind, self.key = kind, key
        self._entries: dict[str, T] = {}

    def register(self, name: str, entry: T) -> T:
        """Add ``entry`` under ``name``; a name can be registered once (``ValueError`` otherwise)."""
        if name in self._entries:
            raise ValueError(f"{self.kind} {name!r} is registered already")
        self._entries[name] = entry
        return entry

    def unregister(self, name: str) -> None:
        """Remove ``name`` (a test's toy entry, once the test is done)."""
        self._entries.pop(name, None)

    def get(self, name: str, where: str | None = None) -> T:
        """The entry of ``name``; :class:`InputError` naming ``where`` and the allowed names otherwise."""
        try:
            return self._entries[name]
        except (KeyError, TypeError):
            raise InputError(f"{where or self.key}: unknown {self.kind} {name!r}; allowed: {', '.join(self._entries)}") from None

    def names(self) -> tuple[str, ...]:
        return tuple(self._entries)

    def items(self):
        return self._entries.items()

    def __contains__(self, name) -> bool:
        return name in self._entries

    def __iter__(self) -> Iterator[str]:
        return iter(self._entries)

    def __len__(self) -> int:
        return len(self._entries)
