"""File helpers shared by the scripts (and by any code that writes results): standard library only."""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path


def write_json_atomic(path: Path | str, data: object) -> None:
    """Write ``data`` as indented JSON next to ``path``, then rename it into place.

    Readers see the old file or the complete new one, never a half-written file; if writing fails, the
    temporary file is removed and ``path`` is left as it was.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.NamedTemporaryFile("w", dir=path.parent, suffix=".tmp", delete=False) as f:
        try:
            json.dump(data, f, indent=2, sort_keys=True)
            f.write("\n")
        except BaseException:
            f.close()
            os.unlink(f.name)
            raise
    os.replace(f.name, path)
