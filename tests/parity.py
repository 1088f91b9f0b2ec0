"""Temporary: ``tests/batching.py`` (moved to ``tests/support/`` on another branch) still imports these from here.

Delete this file at the merge, once the helper imports ``jsonable`` and ``values_equal`` from
``scripts.reference.parity``.
"""

from scripts.reference.parity import jsonable, values_equal

__all__ = ["jsonable", "values_equal"]
