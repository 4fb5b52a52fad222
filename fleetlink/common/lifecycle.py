"""``StartStop``: ``with`` for objects that are started and stopped."""

from __future__ import annotations

from types import TracebackType
from typing import Self


class StartStop:
    """``with obj:`` calls ``obj.start()`` on entry (and gives ``obj``) and ``obj.stop()`` on exit."""

    def start(self) -> object:
        """Start the object's work; subclasses implement it (the result is not used by ``with``)."""
        raise NotImplementedError

    def stop(self) -> None:
        """Stop what ``start()`` started; subclasses implement it."""
        raise NotImplementedError

    def __enter__(self) -> Self:
        self.start()
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()
