"""Per-object tracker state as rows of named arrays (a struct of arrays), kept and appended together."""

from __future__ import annotations

import numpy as np

_MIN_CAPACITY = 16


class Rows:
    """Rows of the arrays named in `_FIELDS` (each with the objects on its first axis), which a subclass
    creates empty in its `__init__`.

    Each field is a view of the first `len(self)` rows of a larger array, so that appending a row costs the
    row, not a copy of every row (the capacity doubles when it runs out), and removing rows moves only the
    rows after the first one removed. The views are plain instance attributes, made again when the rows
    change, so that reading a field (dozens of times per tracker frame) is an attribute lookup. Assigning a
    field writes into its rows; a view taken before an `append` or `keep` may no longer be the field's.
    """

    _FIELDS: tuple[str, ...] = ()

    def __setattr__(self, name: str, value) -> None:
        if name not in self._FIELDS:
            object.__setattr__(self, name, value)
            return
        store = self.__dict__.setdefault("_store", {})
        if name in store:
            store[name][: self._count] = value
            return
        value = np.asarray(value)
        if not store:
            object.__setattr__(self, "_count", value.shape[0])
        if value.shape[0] != self._count:
            raise ValueError(f"{type(self).__name__}.{name}: {value.shape[0]} rows, the others have {self._count}")
        array = np.empty((max(_MIN_CAPACITY, value.shape[0]),) + value.shape[1:], dtype=value.dtype)
        array[: value.shape[0]] = value
        store[name] = array
        self.__dict__[name] = array[: self._count]

    def __len__(self) -> int:
        return self._count

    def _views(self) -> None:
        for name, array in self._store.items():
            self.__dict__[name] = array[: self._count]

    def keep(self, mask: np.ndarray) -> None:
        """Keeps the rows where `mask` (N,) is True, in every array, in their order."""
        mask = np.asarray(mask, dtype=bool)
        dropped = np.flatnonzero(~mask)
        if not dropped.size:
            return
        first, kept = int(dropped[0]), int(mask.sum())
        for array in self._store.values():
            array[first:kept] = array[first: self._count][mask[first:]]
        self._count = kept
        self._views()

    def append(self, **rows) -> None:
        """Appends rows given for every field by name, each array with the new rows on its first axis."""
        n = self._count
        m = np.asarray(rows[self._FIELDS[0]]).shape[0]
        try:
            for name in self._FIELDS:
                array = self._store[name]
                if n + m > array.shape[0]:
                    # The field's view goes first, so that the old array is freed as soon as it is copied (a
                    # 240-camera rig's point arrays are megabytes, and the allocator reuses what is freed).
                    del self.__dict__[name]
                    grown = np.empty((max(2 * array.shape[0], n + m),) + array.shape[1:], dtype=array.dtype)
                    grown[:n] = array[:n]
                    self._store[name] = array = grown
                array[n: n + m] = rows[name]
            self._count = n + m
        finally:
            self._views()
