"""Locate robot model files and prepare their XML text for Drake's parser.

Cassie, G1, iCub and Talos come from the installed ``example-robot-data`` package, found at
run time (its files are never copied); a user's robot names its own file and package folders.
The XML is edited in memory before parsing:
- every ``<collision>`` is dropped: the station gives each foot its own sole contact
  points, and Drake cannot build convex hulls of G1's ``.STL`` collision meshes;
- every URDF ``<transmission>`` is dropped: RobotModel gives each non-passive joint one
  actuator itself (Drake would add a second from Talos's transmissions);
- a ``<mimic>`` whose joint or leader is not a 1-DoF joint (revolute, continuous,
  prismatic) is dropped: there is no motion to couple, and Drake rejects the file (Talos's
  gripper fingers are ``fixed`` joints that mimic the gripper motor). A mimic between two
  1-DoF joints is kept for Drake;
- the ``friction`` of a joint's ``<dynamics>`` is dropped (Drake ignores it, with a warning);
- a URDF link of zero mass gets zero rotational inertia too (Bolt's foot balls give a mass of 0
  with a nonzero inertia, which Drake rejects with a warning and replaces by a 1 kg body);
- joints listed in ``weld_joints`` become fixed (rigid springs);
- bodies listed in ``remove_bodies`` go, with every joint touching them (Cassie's
  loop-closing rods, whose ``ball`` joints would make a kinematic loop);
- with ``base_frame_rpy`` a massless link ``romoco_base`` becomes the URDF's root, welded
  to the file's root link at that orientation, so the floating base is x forward, z up.
Effort limits are read from the XML because Drake keeps them only for URDF
transmissions, which are dropped.
"""

from __future__ import annotations

import functools
import importlib.metadata
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from romoco_drake.errors import RomocoError
from romoco_drake.robots.config import ModelSource
from romoco_drake.robots.meshes import stl_as_obj

ERD_PACKAGE = "example-robot-data"
BASE_FRAME_LINK = "romoco_base"
ONE_DOF_JOINTS = {"revolute", "continuous", "prismatic"}
_PACKAGE_DIR = Path(__file__).resolve().parents[1]


def _data_dir(name: str) -> Path:
    """The repository's top-level ``name`` folder, wherever the install put it.

    A wheel ships it inside the package as ``romoco_drake/_data/<name>`` (see pyproject.toml);
    an editable install or a source checkout reads it in place, next to ``romoco_drake/``.
    """
    shipped = _PACKAGE_DIR / "_data" / name
    return shipped if shipped.is_dir() else _PACKAGE_DIR.parent / name


ROBOTS_DIR = _data_dir("robots")
MODELS_DIR = _data_dir("models")
DIAGRAMS_DIR = _data_dir("diagrams")


@functools.cache
def example_robot_data_root() -> Path:
    """The installed ``share/example-robot-data`` folder (it holds package.xml)."""
    try:
        files = importlib.metadata.distribution(ERD_PACKAGE).files or []
    except importlib.metadata.PackageNotFoundError:
        raise RomocoError(
            "the PyPI package 'example-robot-data' is not installed (pip install example-robot-data)"
        ) from None
    for f in files:
        parts = Path(str(f)).parts
        if parts[-1] == "package.xml" and len(parts) >= 2 and parts[-2] == ERD_PACKAGE:
            return Path(f.locate()).resolve().parent
    raise RomocoError("example-robot-data is installed but its share/example-robot-data is missing")


def package_paths(source: ModelSource) -> dict[str, Path]:
    """Packages to register with Drake's PackageMap for ``source``."""
    packages = {name: Path(folder) for name, folder in source.package_paths.items()}
    if source.package == ERD_PACKAGE:
        packages[ERD_PACKAGE] = example_robot_data_root()
    elif source.package == "romoco_models":
        packages["romoco_models"] = MODELS_DIR
    return packages


def model_path(source: ModelSource) -> Path:
    if source.package is None:
        return Path(source.file)
    return package_paths(source)[source.package] / source.file


def resolve_relative_paths(source: ModelSource, folder: Path) -> None:
    """Makes a user model's relative ``file`` and ``package_paths`` relative to ``folder``."""
    if source.package is None:
        source.file = str((folder / source.file).resolve())
    source.package_paths = {name: str((folder / p).resolve()) for name, p in source.package_paths.items()}


@dataclass(frozen=True)
class PreparedModel:
    """Edited model text ready for ``Parser.AddModelsFromString``."""

    text: str
    file_type: str  # "urdf" or "sdf"
    path: Path
    effort_limits: dict[str, float]
    velocity_limits: dict[str, float]


def _float_or_none(text: str | None) -> float | None:
    try:
        return float(text) if text is not None else None
    except ValueError:
        return None


@functools.cache
def _prepare_cached(source_key: tuple) -> PreparedModel:
    package, file, packages, weld_joints, remove_bodies, base_frame_rpy = source_key
    source = ModelSource(package=package, file=file, package_paths=dict(packages),
                         weld_joints=list(weld_joints), remove_bodies=list(remove_bodies),
                         base_frame_rpy=None if base_frame_rpy is None else list(base_frame_rpy))
    path = model_path(source)
    try:
        root = ET.parse(path).getroot()
    except OSError as e:
        raise RomocoError(f"{path}: cannot read model file ({e.strerror})") from None
    except ET.ParseError as e:
        raise RomocoError(f"{path}: malformed XML ({e})") from None
    file_type = "sdf" if root.tag == "sdf" else "urdf"
    if file_type == "urdf" and root.tag != "robot":
        raise RomocoError(f"{path}: not a URDF or SDFormat file (root <{root.tag}>)")

    # Parent map for removals anywhere in the tree.
    parents = {child: parent for parent in root.iter() for child in parent}
    for collision in list(root.iter("collision")):
        parents[collision].remove(collision)
    _visual_stl_to_obj(root, package_paths(source), path)
    # Gazebo-only elements Drake would warn about; transmissions (RobotModel adds the actuators).
    for tag in ("plugin", "self_collide") + (("transmission",) if file_type == "urdf" else ()):
        for el in list(root.iter(tag)):
            parents[el].remove(el)
    for dynamics in root.iter("dynamics"):
        dynamics.attrib.pop("friction", None)
    if file_type == "urdf":
        _zero_massless_inertia(root)

    joints = _remove_and_weld(root, parents, path, remove_bodies, weld_joints)
    if file_type == "urdf":
        _drop_uncoupled_mimics(joints)
        if base_frame_rpy is not None:
            _add_base_frame(root, path, base_frame_rpy)
    elif base_frame_rpy is not None:
        raise RomocoError(f"{path}: base_frame_rpy is for URDF models only")

    efforts, velocities = _joint_limits(joints, file_type)
    return PreparedModel(ET.tostring(root, encoding="unicode"), file_type, path, efforts, velocities)


def _remove_and_weld(root: ET.Element, parents: dict, path: Path, remove_bodies, weld_joints
                     ) -> dict[str, ET.Element]:
    """Removes the ``remove_bodies`` links with their joints, makes ``weld_joints`` fixed; returns
    the joints left, by name."""
    links = {el.get("name"): el for el in root.iter("link")}
    joints = {el.get("name"): el for el in root.iter("joint")}
    for name in remove_bodies:
        if name not in links:
            raise RomocoError(f"{path}: remove_bodies names unknown link '{name}'")
        parents[links[name]].remove(links[name])
        for jname, joint in list(joints.items()):
            ends = {_joint_end(joint, "parent"), _joint_end(joint, "child")}
            if name in ends and joint in parents and joint in list(parents[joint]):
                parents[joint].remove(joint)
                del joints[jname]
    for name in weld_joints:
        if name not in joints:
            raise RomocoError(f"{path}: weld_joints names unknown joint '{name}'")
        joint = joints[name]
        joint.set("type", "fixed")
        for tag in ("axis", "limit", "dynamics"):
            for el in list(joint.findall(tag)):
                joint.remove(el)
    return joints


def _joint_limits(joints: dict[str, ET.Element], file_type: str) -> tuple[dict[str, float], dict[str, float]]:
    """(effort, velocity) limits by joint name, the positive ones; an SDFormat joint's effort is set
    to 0 in the XML (Drake's parser would make an actuator; RobotModel adds them itself)."""
    efforts, velocities = {}, {}
    for name, joint in joints.items():
        if file_type == "sdf" and joint.find("axis") is not None and joint.find("axis/limit") is None:
            ET.SubElement(joint.find("axis"), "limit")
        limit = joint.find("limit") if file_type == "urdf" else joint.find("axis/limit")
        if limit is None:
            continue
        if file_type == "urdf":
            effort, velocity = limit.get("effort"), limit.get("velocity")
        else:
            effort = limit.findtext("effort")
            velocity = limit.findtext("velocity")
            # Drake's SDFormat parser makes an actuator for every joint whose effort is
            # not 0 (absent means unlimited); RobotModel adds them itself, from these.
            for el in list(limit.findall("effort")):
                limit.remove(el)
            ET.SubElement(limit, "effort").text = "0"
        if (e := _float_or_none(effort)) is not None and e > 0:
            efforts[name] = e
        if (v := _float_or_none(velocity)) is not None and v > 0:
            velocities[name] = v
    return efforts, velocities


def _zero_massless_inertia(root: ET.Element) -> None:
    """Sets the ``<inertia>`` of every zero-mass URDF ``<inertial>`` to zero."""
    for inertial in root.iter("inertial"):
        mass, inertia = inertial.find("mass"), inertial.find("inertia")
        if mass is not None and inertia is not None and _float_or_none(mass.get("value")) == 0.0:
            for key in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"):
                inertia.set(key, "0")


def _drop_uncoupled_mimics(joints: dict[str, ET.Element]) -> None:
    """Removes each ``<mimic>`` whose joint or leader has no single degree of freedom."""
    for joint in joints.values():
        mimic = joint.find("mimic")
        if mimic is None:
            continue
        leader = joints.get(mimic.get("joint"))
        leader_type = None if leader is None else leader.get("type")
        if joint.get("type") not in ONE_DOF_JOINTS or leader_type not in ONE_DOF_JOINTS:
            joint.remove(mimic)


def _add_base_frame(root: ET.Element, path: Path, rpy: tuple[float, ...]) -> None:
    """Makes a massless ``romoco_base`` link the root, welded to the old root at ``rpy``."""
    children = {_joint_end(j, "child") for j in root.iter("joint")}
    roots = [link.get("name") for link in root.iter("link") if link.get("name") not in children]
    if len(roots) != 1:
        raise RomocoError(f"{path}: base_frame_rpy needs one root link, found {len(roots)}")
    ET.SubElement(root, "link", name=BASE_FRAME_LINK)
    joint = ET.SubElement(root, "joint", name=f"{BASE_FRAME_LINK}_joint", type="fixed")
    ET.SubElement(joint, "parent", link=BASE_FRAME_LINK)
    ET.SubElement(joint, "child", link=roots[0])
    ET.SubElement(joint, "origin", xyz="0 0 0", rpy=" ".join(f"{a:.17g}" for a in rpy))


def _resolve_uri(uri: str, packages: dict[str, Path], model_file: Path) -> Path:
    for scheme in ("package://", "model://"):
        if uri.startswith(scheme):
            package, _, rest = uri[len(scheme):].partition("/")
            if package in packages:
                return packages[package] / rest
    if uri.startswith("file://"):
        return Path(uri[len("file://"):])
    return model_file.parent / uri


def _visual_stl_to_obj(root: ET.Element, packages: dict[str, Path], model_file: Path) -> None:
    """Points STL visual meshes at cached OBJ twins Meshcat can show."""
    for mesh in root.iter("mesh"):
        uri_el = mesh.find("uri")  # SDFormat
        uri = uri_el.text.strip() if uri_el is not None and uri_el.text else mesh.get("filename")
        if not uri or not uri.lower().endswith(".stl"):
            continue
        stl = _resolve_uri(uri, packages, model_file)
        if not stl.exists():
            raise RomocoError(f"{model_file}: visual mesh {uri} not found")
        obj = stl_as_obj(stl).as_uri()
        if uri_el is not None:
            uri_el.text = obj
        else:
            mesh.set("filename", obj)


def _joint_end(joint: ET.Element, tag: str) -> str | None:
    el = joint.find(tag)
    if el is None:
        return None
    return el.get("link") or (el.text or "").strip()


def prepare_model(source: ModelSource) -> PreparedModel:
    """Reads and edits the model file of ``source`` (cached per source)."""
    rpy = None if source.base_frame_rpy is None else tuple(source.base_frame_rpy)
    return _prepare_cached(
        (source.package, source.file, tuple(sorted(source.package_paths.items())),
         tuple(source.weld_joints), tuple(source.remove_bodies), rpy)
    )
