"""Binary STL writing and reading (float32 as the format requires)."""
from __future__ import annotations

import struct
from pathlib import Path
from typing import BinaryIO

import numpy as np

from rvcad.mesh import Mesh

_STL_DTYPE = np.dtype([("normal", "<f4", (3,)), ("v", "<f4", (3, 3)), ("attr", "<u2")])


def stl_bytes(mesh: Mesh, header: str = "") -> bytes:
    """Binary STL of the mesh (float32 as the format requires; normals from the float64 mesh)."""
    v = mesh.vertices
    tri = v[mesh.faces]
    nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    ln = np.linalg.norm(nrm, axis=1, keepdims=True)
    nrm = np.divide(nrm, ln, out=np.zeros_like(nrm), where=ln > 0)
    rec = np.zeros(len(tri), dtype=_STL_DTYPE)
    rec["normal"] = nrm
    rec["v"] = tri
    head = header.encode("ascii", "replace")[:80].ljust(80, b" ")
    return head + struct.pack("<I", len(tri)) + rec.tobytes()


def write_stl(target: str | Path | BinaryIO, mesh: Mesh, header: str = "") -> int:
    """Write a binary STL; returns the number of bytes. ``target`` is a path or a binary file."""
    data = stl_bytes(mesh, header)
    if isinstance(target, (str, Path)):
        Path(target).write_bytes(data)
    else:
        target.write(data)
    return len(data)


def read_stl(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Read a binary STL: triangles (T, 3, 3) float64 and normals (T, 3), mm (for checks)."""
    data = Path(path).read_bytes()
    n = struct.unpack("<I", data[80:84])[0]
    rec = np.frombuffer(data, dtype=_STL_DTYPE, count=n, offset=84)
    return rec["v"].astype(np.float64), rec["normal"].astype(np.float64)


__all__ = ["read_stl", "stl_bytes", "write_stl"]
