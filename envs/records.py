"""Per-slot records: a family keeps the state of a slot in one row of a table, and reads each field through an
attribute that is a view of that field for all slots.

A reset then writes a slot's whole state in one assignment (several slots' in one scatter), while a step reads and
writes every field as an ordinary array with a leading slot axis. Two table layouts are in use:

* a structured array, one record per slot (Searing Spotlights' settings, episode state and spotlights), whose whole
  records are copied as opaque bytes (:func:`as_bytes`);
* a plain integer table whose fields are named groups of columns (:class:`Columns`; Mortar Mayhem's slot state),
  written from lists of ints.

:func:`bind_fields` gives the owner one attribute view per field, for either layout.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np


class Columns:
    """The layout of an integer table: ``fields`` are (name, width, what it holds), in column order."""

    def __init__(self, fields: Sequence[tuple[str, int, str]]) -> None:
        self.fields = tuple(fields)
        self.start: dict[str, int] = {}  # first column of each field
        self.widths: dict[str, int] = {}
        width = 0
        for name, columns, _ in self.fields:
            self.start[name], self.widths[name] = width, columns
            width += columns
        self.width = width

    def view(self, table: np.ndarray, name: str) -> np.ndarray:
        """The columns of field ``name`` (one column: a 1-d view, else (slots, width))."""
        start, width = self.start[name], self.widths[name]
        return table[:, start] if width == 1 else table[:, start : start + width]


def bind_fields(owner: Any, table: np.ndarray, columns: Columns | None = None) -> None:
    """Set one attribute of ``owner`` per field of ``table``: a view of the field in every slot's record.

    ``table`` is a structured array with one record per slot, or, with ``columns``, an integer table laid out by it.
    """
    if columns is None:
        for name in table.dtype.names:
            setattr(owner, name, table[name])
    else:
        for name, _, _ in columns.fields:
            setattr(owner, name, columns.view(table, name))


def as_bytes(records: np.ndarray | np.void) -> np.ndarray:
    """The same records as opaque items of their size: whole-record copies then skip numpy's field-by-field casts
    (a fancy-indexed structured assignment costs tens of microseconds; as bytes, a fraction of one)."""
    records = np.asarray(records)
    return records.view(np.dtype((np.void, records.dtype.itemsize)))
