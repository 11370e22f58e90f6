"""STL → OBJ conversion for visual meshes.

Drake's Meshcat shows only .obj/.gltf/.dae meshes, and G1's and Cassie's visuals in
example-robot-data are STL. The first time a model is loaded its STL visuals are
converted into a per-user cache (never into the repository), keyed by the source path,
size and modification time.
"""

from __future__ import annotations

import hashlib
import os
import struct
import tempfile
from pathlib import Path

import numpy as np


def cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "romoco_drake" / "meshes"


def read_stl(path: Path) -> np.ndarray:
    """Triangles (N, 3, 3) of a binary or ASCII STL file."""
    data = path.read_bytes()
    if len(data) >= 84:
        (count,) = struct.unpack_from("<I", data, 80)
        if 84 + 50 * count == len(data):
            record = np.dtype([("normal", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
            return np.frombuffer(data, dtype=record, count=count, offset=84)["v"].astype(float)
    vertices = [
        [float(x) for x in line.split()[1:4]]
        for line in data.decode("ascii", errors="replace").splitlines()
        if line.strip().startswith("vertex")
    ]
    return np.array(vertices, dtype=float).reshape(-1, 3, 3)


def write_obj(triangles: np.ndarray, path: Path) -> None:
    """Writes triangles as an OBJ with shared vertices, through a temporary file of this writer's
    own: processes converting the same mesh at once (parallel test workers) each replace the
    finished file atomically; a shared temporary name made one's rename fail."""
    verts, faces = np.unique(triangles.reshape(-1, 3), axis=0, return_inverse=True)
    faces = faces.reshape(-1, 3) + 1
    with tempfile.NamedTemporaryFile("w", dir=path.parent, prefix=f"{path.stem}-", suffix=".tmp",
                                     delete=False) as f:
        f.write("".join(f"v {x:.6g} {y:.6g} {z:.6g}\n" for x, y, z in verts))
        f.write("".join(f"f {a} {b} {c}\n" for a, b, c in faces))
    os.replace(f.name, path)


def stl_as_obj(stl: Path) -> Path:
    """The cached OBJ twin of ``stl``, converting it first if needed."""
    stat = stl.stat()
    key = hashlib.sha1(f"{stl.resolve()}:{stat.st_size}:{stat.st_mtime_ns}".encode()).hexdigest()[:16]
    out = cache_dir() / f"{stl.stem}-{key}.obj"
    if not out.exists():
        out.parent.mkdir(parents=True, exist_ok=True)
        write_obj(read_stl(stl), out)
    return out
