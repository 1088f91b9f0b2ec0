"""Temporary: ``tests/test_mystery_path_generator.py`` (moved on another branch) still imports ``load_mp_paths``
from here. Delete this file at the merge, once that test imports it from ``scripts.reference.trace_format``."""

from scripts.reference.trace_format import load_mp_paths

__all__ = ["load_mp_paths"]
