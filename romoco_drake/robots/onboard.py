"""``romoco new-robot``: a robot YAML skeleton inferred from a biped's model file.

What is read from the model (parsed by Drake at its zero configuration, the legs hanging):
- the floating base: the body Drake gives a floating joint; a URDF whose ankles both sit at the
  front of their soles faces backward and is re-rooted at an x-forward frame (base_frame_rpy);
- the feet: on each side, the lowest body that ends a chain of moving joints (its geometry
  and that of bodies welded to it count), left and right from link names, else from the
  base frame's +y;
- the legs: the moving joints between the base and each foot; every other moving joint
  (waist, arms, head, joints both legs share) is locked;
- the sole: the lowest collision geometry (boxes, spheres, cylinders, STL, OBJ and COLLADA
  meshes; visual geometry when a foot has none) within 0.5 mm of its lowest point, reduced to
  the toe and heel edges of the largest quadrilateral inside it (corners of a box or of contact
  spheres are kept exactly; a rounded toe is cut back to where the sole is wide);
  a sole narrower than 1.5 cm is a line foot, a smaller one a point foot;
- joint limits and effort limits (listed in the YAML's comments);
- the nominal pose: the existing standing IK at 92 % of the straight-leg CoM height, whose
  leg angles become ``joint_guess``.
What is guessed, and said so in the YAML: gains (kp = 2 N·m/rad per N·m of effort limit),
LIP walking parameters (t_ss from the LIP time constant), command limits. What cannot be
inferred is listed (closed kinematic loops, passive joints, missing effort limits).
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from romoco_drake.errors import RomocoError
from romoco_drake.robots.meshes import read_stl
from romoco_drake.rom.polygon import convex_hull_2d
from romoco_drake.spatial import GRAVITY

LOWEST_BAND = 5e-4  # m: geometry this close to a foot's lowest point is sole (a 15 mm ball's
# cap is then 8 mm across: still a point)
LINE_WIDTH = 0.015  # m: a sole narrower than this is a line (and shorter too: a point)
CROUCH = 0.92  # nominal CoM height / straight-leg CoM height
KP_PER_EFFORT = 2.0  # (N·m/rad) per N·m of effort limit: G1's 88 N·m hips get 176
KD_PER_KP = 1.0 / 40.0


@dataclass
class Inferred:
    """What ``infer`` found: YAML fields, the facts behind them, and what it could not infer."""

    name: str
    model: dict
    base_body: str
    foot_type: str
    feet: dict  # side -> {"body", "points", "up"}
    leg_joints: dict  # side -> [joint names]
    locked_joints: list[str]
    joints: list[dict]  # name, lower, upper, effort, velocity
    knee_seed: dict  # knee joint -> a bent angle, so the standing IK crouches on bent knees
    com_height_straight: float
    foot_separation: float
    leg_length: float
    notes: list[str] = field(default_factory=list)


# ----------------------------------------------------------------------------- geometry
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


# ----------------------------------------------------------------------------- model
def _side_from_name(name: str) -> str | None:
    lowered = name.lower()
    for side, short in (("left", "l"), ("right", "r")):
        if side in lowered or re.search(rf"(^|[_\-.]){short}([_\-.]|$)", lowered):
            return side
    return None


def _user_source(model_file: Path | None, package_dirs: list[Path]) -> tuple[dict, dict[str, Path]]:
    """The YAML ``model:`` entry for ``model_file`` and the package folders its URIs may need:
    the ``--package-path`` packages and the installed example-robot-data."""
    from romoco_drake.robots.source import ERD_PACKAGE, example_robot_data_root

    packages: dict[str, Path] = {}
    for folder in package_dirs:
        if not folder.is_dir():
            raise RomocoError(f"--package-path {folder}: not a folder")
        found = [folder / "package.xml"] if (folder / "package.xml").exists() else sorted(
            folder.glob("*/package.xml")) + sorted(folder.glob("*/*/package.xml"))
        if not found:
            raise RomocoError(f"--package-path {folder}: no package.xml in it or its subfolders")
        for manifest in found:
            try:
                name = (ET.parse(manifest).getroot().findtext("name") or "").strip()
            except ET.ParseError:
                name = ""
            packages[name or manifest.parent.name] = manifest.parent.resolve()
    try:
        packages[ERD_PACKAGE] = example_robot_data_root()
    except RomocoError:
        pass
    if model_file is None:
        return {}, packages
    model_file = model_file.resolve()
    erd = packages.get(ERD_PACKAGE)
    if erd is not None and model_file.is_relative_to(erd):
        entry = {"package": ERD_PACKAGE, "file": str(model_file.relative_to(erd))}
    else:
        entry = {"file": str(model_file)}
    if any(name != ERD_PACKAGE for name in packages):
        entry["package_paths"] = {n: str(p) for n, p in packages.items() if n != ERD_PACKAGE}
    return entry, packages


def _knee(plant, context, leg: list, foot: str, fwd_W: np.ndarray, left_W: np.ndarray):
    """(name, bent angle) of the leg's knee: the lateral-axis joint nearest mid-leg.

    It bends the way its limits leave most room (a knee's range is one-sided), or, for a
    symmetric range, the way that puts the knee ahead of the hip-foot line.
    """
    p_foot = plant.GetBodyByName(foot).EvalPoseInWorld(context).translation()
    p_hip = leg[0].frame_on_child().CalcPoseInWorld(context).translation() if leg else p_foot
    mid = (p_hip[2] + p_foot[2]) / 2
    best = None
    for joint in leg:
        if not hasattr(joint, "revolute_axis"):
            continue
        X = joint.frame_on_child().CalcPoseInWorld(context)
        axis = X.rotation().multiply(joint.revolute_axis())
        if abs(axis @ left_W) < 0.9:
            continue
        if best is None or abs(X.translation()[2] - mid) < abs(best[1].translation()[2] - mid):
            best = (joint, X, axis)
    if best is None:
        return None
    joint, X, axis = best
    sign = -1.0 if fwd_W @ np.cross(axis, p_foot - X.translation()) > 0 else 1.0
    upper, lower = joint.position_upper_limits()[0], -joint.position_lower_limits()[0]
    if max(upper, lower) > 2 * min(upper, lower):
        sign = 1.0 if upper > lower else -1.0
    return joint.name(), 0.6 * sign


def model_file_path(model: str, package_dirs: list[Path] = ()) -> Path:
    """A MODEL_FILE argument as a path: a file path, or ``package://PKG/...`` in the installed
    example-robot-data or a ``--package-path`` package."""
    if not model.startswith("package://"):
        return Path(model)
    package, _, rest = model[len("package://"):].partition("/")
    _, packages = _user_source(None, list(package_dirs))
    if package not in packages:
        raise RomocoError(f"{model}: unknown package '{package}' (known: {', '.join(packages) or 'none'})")
    return packages[package] / rest


def infer(model_file: Path, name: str, package_dirs: list[Path] = (),
          base_frame_rpy: list[float] | None = None) -> Inferred:
    """Reads a biped's model file and infers the structural fields of its robot YAML.

    ``base_frame_rpy``: re-root the model at a frame so turned (ModelSource.base_frame_rpy); a
    URDF whose feet show it faces backward is re-rooted by a half turn about z.
    """
    from pydrake.multibody.parsing import Parser
    from pydrake.multibody.plant import MultibodyPlant

    from romoco_drake.robots.config import ModelSource
    from romoco_drake.robots.source import _resolve_uri, prepare_model

    if not model_file.is_file():
        raise RomocoError(f"{model_file}: no such model file")
    entry, packages = _user_source(model_file, list(package_dirs))
    source = ModelSource(file=str(model_file.resolve()), base_frame_rpy=base_frame_rpy,
                         package_paths={n: str(p) for n, p in packages.items()})
    if base_frame_rpy is not None:
        entry["base_frame_rpy"] = [round(a, 6) for a in base_frame_rpy]
    prepared = prepare_model(source)
    plant = MultibodyPlant(0.0)
    parser = Parser(plant)
    for pkg, folder in packages.items():
        parser.package_map().Add(pkg, str(folder))
    try:
        parser.AddModelsFromString(prepared.text, prepared.file_type)
    except RuntimeError as e:
        raise RomocoError(f"{model_file}: cannot parse model ({str(e).strip().splitlines()[0]})") from None
    plant.Finalize()
    context = plant.CreateDefaultContext()
    notes: list[str] = []

    floating = [plant.get_body(i) for i in plant.GetFloatingBaseBodies()]
    if len(floating) != 1:
        raise RomocoError(f"{model_file}: expected one floating base body, found {len(floating)}")
    base = floating[0]

    def resolve(uri: str) -> Path:
        for scheme in ("package://", "model://"):
            package = uri[len(scheme):].partition("/")[0] if uri.startswith(scheme) else None
            if package is not None and package not in packages:
                raise RomocoError(f"{model_file}: {uri}: unknown package '{package}' "
                                  "(give its folder with --package-path)")
        return _resolve_uri(uri, packages, prepared.path)

    xml_root = ET.parse(prepared.path).getroot()
    collision = link_geometry(xml_root, "collision", resolve)
    visual = link_geometry(xml_root, "visual", resolve)

    parent_joint, children = {}, {}
    for i in plant.GetJointIndices():
        joint = plant.get_joint(i)
        if joint.parent_body().index() == plant.world_body().index():
            continue
        parent_joint[joint.child_body().name()] = joint
        children.setdefault(joint.parent_body().name(), []).append(joint.child_body().name())

    def moving(joint) -> bool:
        return joint.num_velocities() >= 1

    def welded_group(body: str) -> list[str]:
        group, stack = [], [body]
        while stack:
            b = stack.pop()
            group.append(b)
            stack += [c for c in children.get(b, []) if not moving(parent_joint[c])]
        return group

    def has_moving_descendant(body: str) -> bool:
        return any(moving(parent_joint[c]) or has_moving_descendant(c) for c in children.get(body, []))

    X_WB = {b: plant.GetBodyByName(b).EvalPoseInWorld(context) for b in parent_joint} | {
        base.name(): base.EvalPoseInWorld(context)}

    def cloud_W(bodies: list[str]) -> tuple[np.ndarray, str]:
        for kind, table in (("collision", collision), ("visual", visual)):
            clouds = [X_WB[b].multiply(table[b].T).T for b in bodies if b in table]
            if clouds:
                return np.vstack(clouds), kind
        return np.array([X_WB[b].translation() for b in bodies]), "frame origins"

    distal = [b for b, j in parent_joint.items() if moving(j) and not has_moving_descendant(b)]
    R_WBase = X_WB[base.name()].rotation().matrix()
    fwd_W, left_W = R_WBase[:, 0], R_WBase[:, 1]
    candidates = {}
    for body in distal:
        cloud, kind = cloud_W(welded_group(body))
        side = _side_from_name(body) or ("left" if left_W @ X_WB[body].translation() > 0 else "right")
        low = cloud[:, 2].min()
        if side not in candidates or low < candidates[side][1]:
            candidates[side] = (body, low, cloud, kind)
    if set(candidates) != {"left", "right"}:
        ends = ", ".join(distal) or "none"
        raise RomocoError(f"{model_file}: cannot find two legs (bodies ending a joint chain: {ends})")

    def path_to_base(body: str) -> list[str]:
        joints = []
        while body != base.name():
            joint = parent_joint[body]
            if moving(joint):
                joints.append(joint.name())
            body = joint.parent_body().name()
        return joints[::-1]

    legs = {side: path_to_base(c[0]) for side, c in candidates.items()}
    shared = set(legs["left"]) & set(legs["right"])
    if shared:
        notes.append(f"joints both legs pass through are locked: {', '.join(sorted(shared))}")
        legs = {s: [j for j in js if j not in shared] for s, js in legs.items()}
    all_moving = [joint for joint in parent_joint.values() if moving(joint)]
    by_name = {j.name(): j for j in all_moving}
    leg_set = set(legs["left"]) | set(legs["right"])
    locked = [j.name() for j in all_moving if j.name() not in leg_set]

    feet, types, centers, heel_first = {}, set(), {}, 0
    for side, (body, low, cloud, kind) in candidates.items():
        if kind != "collision":
            notes.append(f"feet.{side}: sole from {kind} (no collision geometry on '{body}'); check it")
        sole = cloud[cloud[:, 2] <= low + LOWEST_BAND]
        sl = np.column_stack([sole @ fwd_W, sole @ left_W])
        foot_type, outline = sole_outline(sl)
        types.add(foot_type)
        X = X_WB[body]
        p_W = np.array([fwd_W * s + left_W * lat for s, lat in outline])
        p_W[:, 2] = low
        points = X.inverse().multiply(p_W.T).T
        up = X.rotation().inverse().multiply(np.array([0.0, 0.0, 1.0]))
        centers[side] = p_W.mean(axis=0)
        ankle = X.translation() @ fwd_W
        heel_first += foot_type == "plane" and ankle - sl[:, 0].min() > 2 * (sl[:, 0].max() - ankle)
        feet[side] = {"body": body, "points": points, "up": up}
    if len(types) != 1:
        raise RomocoError(f"{model_file}: the feet differ in kind ({', '.join(sorted(types))})")
    if heel_first == 2 and base_frame_rpy is None and prepared.file_type == "urdf":
        # Both ankles sit at the front of their soles: the model's x axis points backward.
        turned = infer(model_file, name, package_dirs, base_frame_rpy=[0.0, 0.0, math.pi])
        turned.notes.insert(0, f"the model's root link '{base.name()}' faces backward (the ankles sit at "
                               "the front of the soles): re-rooted at an x-forward frame (base_frame_rpy)")
        return turned

    joints = []
    lower, upper = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    for joint in all_moving:
        k = joint.position_start()
        effort = prepared.effort_limits.get(joint.name())
        joints.append({"name": joint.name(), "lower": float(lower[k]), "upper": float(upper[k]),
                       "effort": effort, "velocity": prepared.velocity_limits.get(joint.name())})
    missing = [j["name"] for j in joints if j["effort"] is None]
    if missing:
        notes.append(f"no effort limit in the model for {len(missing)} joints ({', '.join(missing[:4])}"
                     f"{', ...' if len(missing) > 4 else ''}): set effort_limits or default_effort_limit")
    notes.append("closed kinematic loops and passive (unactuated) joints are not detected: add "
                 "distance_constraints / coupler_constraints / passive_joints if the robot has them")

    knee_seed = {}
    for side, js in legs.items():
        knee = _knee(plant, context, [by_name[j] for j in js], feet[side]["body"], fwd_W, left_W)
        if knee is not None:
            knee_seed[knee[0]] = knee[1]
        else:
            notes.append(f"no knee found on the {side} leg (a joint about the lateral axis); set joint_guess")
    com = plant.CalcCenterOfMassPositionInWorld(context)
    ground = min(c[1] for c in candidates.values())
    hips = [by_name[js[0]].child_body().name() for js in legs.values() if js]
    leg_length = max(X_WB[b].translation()[2] for b in hips) - ground if hips else com[2] - ground
    return Inferred(
        name=name, model=entry, base_body=base.name(), foot_type=types.pop(), feet=feet,
        leg_joints=legs, locked_joints=locked, joints=joints, knee_seed=knee_seed,
        com_height_straight=float(com[2] - ground),
        foot_separation=float(abs((centers["left"] - centers["right"]) @ left_W)),
        leg_length=float(leg_length), notes=notes)


# ----------------------------------------------------------------------------- YAML
def _vec(values) -> str:
    return "[" + ", ".join(f"{round(float(v), 4):g}" for v in values) + "]"


def _limit(value: float) -> str:
    return f"{value:.3f}" if math.isfinite(value) else "none"


def robot_yaml(inf: Inferred, com_height: float, joint_guess: dict[str, float]) -> str:
    """The robot YAML text: inferred fields plain, guessed ones marked ``# guess``."""
    t_ss = max(0.15, round(1.15 * math.sqrt(com_height / GRAVITY), 2))
    swing = round(min(0.1, max(0.03, 0.12 * inf.leg_length)), 3)
    efforts = {j["name"]: j["effort"] for j in inf.joints}
    lines = [
        f"# {inf.name}: written by `romoco new-robot` from {Path(inf.model['file']).name}.",
        "# Lines marked `guess` are starting values to tune; see README.md, 'Adding a robot'.",
        f"name: {inf.name}",
        f"description: {inf.name} biped (from {Path(inf.model['file']).name})",
        "model:",
        *(f"  {k}: {v}" for k, v in inf.model.items() if k != "package_paths"),
    ]
    if "package_paths" in inf.model:
        lines += ["  package_paths:", *(f"    {k}: {v}" for k, v in inf.model["package_paths"].items())]
    lines += [f"base_body: {inf.base_body}", "feet:", f"  type: {inf.foot_type}", "  friction: 0.8  # guess"]
    for side in ("left", "right"):
        foot = inf.feet[side]
        lines += [f"  {side}:", f"    body: {foot['body']}",
                  f"    points: [{', '.join(_vec(p) for p in foot['points'])}]",
                  f"    up: {_vec(foot['up'])}"]
    lines += ["nominal:", f"  com_height: {com_height:.3f}  # {CROUCH:.0%} of the straight-leg CoM height",
              f"  foot_separation: {inf.foot_separation:.3f}"]
    if joint_guess:
        lines += ["  joint_guess:", *(f"    {k}: {v:.3f}" for k, v in joint_guess.items())]
    if inf.locked_joints:
        lines += [f"locked_joints: [{', '.join(inf.locked_joints)}]"]
    if any(e is None for e in efforts.values()):
        lines += ["default_effort_limit: 50.0  # guess: the model gives no effort limit for some joints"]
    lines += ["# guess: kp = 2 N·m/rad per N·m of effort limit, kd = kp / 40.", "gains:"]
    for name, effort in efforts.items():
        kp = round(KP_PER_EFFORT * (effort if effort is not None else 50.0), 1)
        lines.append(f"  - {{joints: {name}, kp: {kp:g}, kd: {round(kp * KD_PER_KP, 2):g}}}")
    lines += [
        "# guess: LIP walking at the nominal CoM height; t_ss = 1.15 sqrt(z0/g), swing 12 % of the leg.",
        "walking:",
        f"  {{t_ss: {t_ss:g}, t_ds: 0.0, z0: {com_height:.3f}, step_width: {inf.foot_separation:.3f}, "
        f"swing_height: {swing:g}}}",
        "# Joints (from the model): lower, upper [rad], effort [N·m], velocity [rad/s]",
        *(f"#   {j['name']}: {_limit(j['lower'])}, {_limit(j['upper'])}, {j['effort']}, {j['velocity']}"
          for j in inf.joints),
    ]
    return "\n".join(lines) + "\n"


def new_robot(model_file: Path, out: Path, package_dirs: list[Path] = ()) -> tuple[str, list[str]]:
    """Infers a robot YAML for ``model_file``, solves its nominal pose, and writes it to ``out``.

    Returns the YAML text and the notes on what could not be inferred.
    """
    import tempfile

    from romoco_drake.robots.model import RobotModel, load_robot_config_file

    name = out.stem
    if not re.fullmatch(r"[A-Za-z0-9_\-]+", name):
        raise RomocoError(f"--out {out}: the file name is the robot's name; use letters, digits, _ and -")
    inf = infer(model_file, name, package_dirs)
    failures = []
    with tempfile.TemporaryDirectory() as tmp:
        trial = Path(tmp) / out.name
        for crouch in (CROUCH, 0.95, 0.88, 0.85):
            com_height = crouch * inf.com_height_straight
            trial.write_text(robot_yaml(inf, com_height, inf.knee_seed))
            try:
                robot = RobotModel(load_robot_config_file(trial), trial)
                q = robot.nominal.q
            except RomocoError as e:
                failures.append(str(e).splitlines()[0])
                continue
            leg = {j for js in inf.leg_joints.values() for j in js}
            guess = {j.name(): round(float(q[j.position_start()]), 3) for j in robot.joints
                     if j.name() in leg and abs(q[j.position_start()]) > 0.02}
            text = robot_yaml(inf, com_height, guess)
            break
        else:
            inf.notes.append(f"no standing pose found by IK ({failures[-1]}); set nominal.joint_guess")
            text = robot_yaml(inf, CROUCH * inf.com_height_straight, {})
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text)
    return text, inf.notes
