"""The format of the reference traces: observation digests and the deterministic gzip JSON files.

Imported by the recorder (inside the isolated reference venv) and by the parity comparison (project venv), so both
sides compute observation digests in exactly the same way. Standard library, numpy and ``agents.runtime.io`` only.

Digest convention: ``image_digest`` hashes an ordinary (row, column, channel) uint8 image. The reference package
returns its observation as obs[x][y][c]; the recorder transposes it with ``obs.transpose(1, 0, 2)`` before hashing.
Our own environments already return (row, column, channel) images and are hashed as they are, with ``obs_digest``.
"""

from __future__ import annotations

import gzip
import hashlib
import json
from pathlib import Path
from typing import Any

import numpy as np

from agents.runtime.io import atomic_write_bytes
from scripts.reference import MP_PATHS_FILE, TRACES_DIR

DIGEST_METHOD = (
    "sha256 hex, first 16 chars, of np.ascontiguousarray(obs.transpose(1,0,2)).tobytes() (uint8); "
    "for Dict observations: digest(visual) + ':' + digest of "
    "np.asarray(vector_observation, dtype=np.float32).tobytes()"
)


def _sha16(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()[:16]


def image_digest(img_hwc: np.ndarray) -> str:
    """Digest of a (row, column, channel) uint8 image."""
    img = np.asarray(img_hwc)
    if img.dtype != np.uint8 or img.ndim != 3:
        raise ValueError(f"expected a (H, W, C) uint8 image, got {img.dtype} {img.shape}")
    return _sha16(np.ascontiguousarray(img).tobytes())


def vector_digest(vec: np.ndarray) -> str:
    """Digest of a vector observation, hashed as float32."""
    return _sha16(np.ascontiguousarray(np.asarray(vec, dtype=np.float32)).tobytes())


def obs_digest(obs: np.ndarray | dict[str, np.ndarray]) -> str:
    """Digest of one observation in (row, column, channel) layout.

    ``obs`` is an image, or a dict with ``visual_observation`` (image) and ``vector_observation`` (the Mortar Mayhem B
    variants); the dict digest is ``image_digest(visual) + ":" + vector_digest(vector)``.
    """
    if isinstance(obs, dict):
        return image_digest(obs["visual_observation"]) + ":" + vector_digest(obs["vector_observation"])
    return image_digest(obs)


def to_jsonable(value: Any) -> Any:
    """Convert numpy arrays/scalars and tuples (recursively) into plain JSON-able python values."""
    if isinstance(value, dict):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


def dump_json_gz(obj: Any, path: Path) -> None:
    """Write ``obj`` as deterministic gzip-compressed JSON (sorted keys, no timestamp, no file name in the header),
    atomically."""
    data = json.dumps(obj, sort_keys=True, separators=(",", ":")).encode()
    atomic_write_bytes(path, gzip.compress(data, compresslevel=9, mtime=0))


def load_json_gz(path: Path) -> Any:
    """Read a gzip-compressed JSON file."""
    with gzip.open(path, "rt", encoding="utf-8") as f:
        return json.load(f)


def load_traces(env_id: str, root: Path = TRACES_DIR) -> dict[str, Any]:
    """Load the recorded reference traces of ``env_id`` (``<root>/<env_id>.json.gz``)."""
    return load_json_gz(Path(root) / f"{env_id}.json.gz")


def load_mp_paths(path: Path = MP_PATHS_FILE) -> dict[str, Any]:
    """Load the recorded Mystery Path / Endless Mystery Path layouts."""
    return load_json_gz(Path(path))
