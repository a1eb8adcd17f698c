"""Per-object tracker state as rows of named arrays (a struct of arrays), kept and appended together."""

from __future__ import annotations

import numpy as np


class Rows:
    """Rows of the arrays named in `_FIELDS` (each with the objects on its first axis), which a subclass
    creates empty in its `__init__`."""

    _FIELDS: tuple[str, ...] = ()

    def __len__(self) -> int:
        return getattr(self, self._FIELDS[0]).shape[0]

    def keep(self, mask: np.ndarray) -> None:
        """Keeps the rows where `mask` (N,) is True, in every array."""
        for name in self._FIELDS:
            setattr(self, name, getattr(self, name)[mask])

    def append(self, **rows) -> None:
        """Appends rows given for every field by name, each array with the new rows on its first axis."""
        for name in self._FIELDS:
            setattr(self, name, np.concatenate([getattr(self, name), rows[name]]))
