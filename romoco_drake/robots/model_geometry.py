"""Geometry read straight from URDF/SDFormat model files: mesh vertices, link shapes, sole outlines.

Used by ``romoco new-robot`` (:mod:`romoco_drake.robots.onboard`) before a robot YAML exists.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from romoco_drake.errors import RomocoError
from romoco_drake.robots.meshes import read_stl
from romoco_drake.rom.polygon import convex_hull_2d

LINE_WIDTH = 0.015  # m: a sole narrower than this is a line (and shorter too: a point)


def _rpy(r: float, p: float, y: float) -> np.ndarray:
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    yaw = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    pitch = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    return yaw @ pitch @ np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])


def _floats(text: str | None, n: int, default: float = 0.0) -> list[float]:
    values = [float(v) for v in (text or "").split()]
    return values + [default] * (n - len(values)) if len(values) < n else values[:n]


def read_mesh_vertices(path: Path) -> np.ndarray:
    """Vertices (N, 3) of an STL, OBJ or COLLADA mesh, in metres and Z up.

    COLLADA positions are scaled by ``<unit meter>`` and turned from the file's ``up_axis``
    to Z up (Y_UP: +90° about x), as mesh importers do.
    """
    suffix = path.suffix.lower()
    if suffix == ".stl":
        return read_stl(path).reshape(-1, 3)
    if suffix == ".obj":
        rows = [line.split()[1:4] for line in path.read_text(errors="replace").splitlines()
                if line.startswith("v ")]
        return np.array(rows, dtype=float).reshape(-1, 3)
    if suffix == ".dae":
        root = ET.parse(path).getroot()
        ns = root.tag.partition("}")[0] + "}" if root.tag.startswith("{") else ""
        arrays = []
        for source in root.iter(f"{ns}source"):
            farr = source.find(f"{ns}float_array")
            if farr is not None and "position" in (source.get("id") or "").lower():
                arrays.append(np.array(farr.text.split(), dtype=float).reshape(-1, 3))
        if not arrays:
            return np.zeros((0, 3))
        vertices = np.vstack(arrays)
        unit = root.find(f"{ns}asset/{ns}unit")
        vertices = vertices * float(unit.get("meter", 1.0)) if unit is not None else vertices
        up = (root.findtext(f"{ns}asset/{ns}up_axis") or "Y_UP").strip()
        turn = {"Y_UP": _rpy(math.pi / 2, 0, 0), "X_UP": _rpy(0, -math.pi / 2, 0)}.get(up, np.eye(3))
        return vertices @ turn.T
    raise RomocoError(f"{path}: mesh format {suffix} is not read (STL, OBJ or COLLADA)")


def _shape_vertices(geometry: ET.Element, sdf: bool, resolve) -> np.ndarray | None:
    """Vertices (N, 3) of one URDF/SDFormat geometry in its own frame; None if unknown."""
    for shape in geometry:
        tag = shape.tag
        if tag == "box":
            size = _floats(shape.findtext("size") if sdf else shape.get("size"), 3)
            return np.array([[sx * size[0] / 2, sy * size[1] / 2, sz * size[2] / 2]
                             for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
        if tag in ("sphere", "cylinder"):
            radius = float(shape.findtext("radius") if sdf else shape.get("radius"))
            if tag == "sphere":
                return np.vstack([np.zeros(3), radius * np.eye(3), -radius * np.eye(3)])
            half = float(shape.findtext("length") if sdf else shape.get("length")) / 2
            angles = np.linspace(0, 2 * math.pi, 24, endpoint=False)
            ring = np.stack([radius * np.cos(angles), radius * np.sin(angles)], axis=1)
            return np.vstack([np.column_stack([ring, np.full(24, z)]) for z in (-half, half)])
        if tag == "mesh":
            uri = (shape.findtext("uri") or "").strip() if sdf else shape.get("filename", "")
            scale = _floats(shape.findtext("scale") if sdf else shape.get("scale"), 3, 1.0)
            mesh = resolve(uri)
            if mesh is None or not mesh.exists():
                return None
            return read_mesh_vertices(mesh) * np.array(scale)
    return None


def link_geometry(root: ET.Element, kind: str, resolve) -> dict[str, np.ndarray]:
    """Per link, the vertices (N, 3) of its ``kind`` ("collision"/"visual") shapes in the link frame."""
    sdf = root.tag == "sdf"
    out: dict[str, np.ndarray] = {}
    for link in root.iter("link"):
        clouds = []
        for element in link.findall(kind):
            geometry = element.find("geometry")
            if geometry is None:
                continue
            vertices = _shape_vertices(geometry, sdf, resolve)
            if vertices is None or len(vertices) == 0:
                continue
            if sdf:
                pose = _floats(element.findtext("pose"), 6)
                xyz, rpy = pose[:3], pose[3:]
            else:
                origin = element.find("origin")
                xyz = _floats(origin.get("xyz") if origin is not None else None, 3)
                rpy = _floats(origin.get("rpy") if origin is not None else None, 3)
            clouds.append(vertices @ _rpy(*rpy).T + np.array(xyz))
        if clouds:
            out[link.get("name")] = np.vstack(clouds)
    return out


def _cross_section(hull: np.ndarray, s: float) -> tuple[float, float] | None:
    """The lateral extent (min, max) of a convex polygon (s, l) along the line at ``s``."""
    ls = []
    for a, b in zip(hull, np.roll(hull, -1, axis=0), strict=True):
        if abs(a[0] - s) < 1e-9:
            ls.append(a[1])
        if (a[0] - s) * (b[0] - s) < 0:
            ls.append(a[1] + (s - a[0]) / (b[0] - a[0]) * (b[1] - a[1]))
    return (min(ls), max(ls)) if ls else None


def sole_outline(points_sl: np.ndarray) -> tuple[str, np.ndarray]:
    """Foot type and sole points (K, 2) in (forward, left) coordinates from the sole's lowest points.

    Plane: toe-left, toe-right, heel-left, heel-right: the cross-sections of the sole's convex
    hull at a toe and a heel line chosen to give the largest quadrilateral (convexity keeps it
    inside the sole; a box's or contact spheres' corners come out exactly, a rounded toe is cut
    back to where the sole is wide). Line: toe, heel. Point: the centroid.
    """
    hull = convex_hull_2d(points_sl)
    s_min, s_max = points_sl[:, 0].min(), points_sl[:, 0].max()
    width = points_sl[:, 1].max() - points_sl[:, 1].min()
    if len(hull) < 3 or width < LINE_WIDTH:
        if s_max - s_min < LINE_WIDTH:
            return "point", points_sl.mean(axis=0, keepdims=True)
        mid = points_sl[:, 1].mean()
        return "line", np.array([[s_max, mid], [s_min, mid]])
    samples = np.linspace(s_min, s_max, 201)
    sections = np.array([_cross_section(hull, s) or (np.nan, np.nan) for s in samples])
    widths = np.nan_to_num(sections[:, 1] - sections[:, 0])
    # Area of the quadrilateral with its toe at sample i and heel at sample j (< i).
    area = np.triu((samples[None, :] - samples[:, None]) * (widths[None, :] + widths[:, None]) / 2, 1)
    heel, toe = np.unravel_index(np.argmax(area), area.shape)
    return "plane", np.array([[samples[toe], sections[toe, 1]], [samples[toe], sections[toe, 0]],
                              [samples[heel], sections[heel, 1]], [samples[heel], sections[heel, 0]]])
