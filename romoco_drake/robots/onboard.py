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
LIP walking parameters (t_ss from the LIP time constant), command limits, and the step reach of
push recovery (from the leg's length and crouch: :mod:`romoco_drake.robots.reach`). What cannot be
inferred is listed (closed kinematic loops, passive joints, missing effort limits).
"""

from __future__ import annotations

import dataclasses
import math
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from romoco_drake.errors import RomocoError
from romoco_drake.robots.model_geometry import link_geometry, sole_outline
from romoco_drake.robots.model_tree import BodyTree, foot_candidates, knee_seeds, split_legs
from romoco_drake.robots.reach import step_reach
from romoco_drake.spatial import GRAVITY

LOWEST_BAND = 5e-4  # m: geometry this close to a foot's lowest point is sole (a 15 mm ball's
# cap is then 8 mm across: still a point)
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


# ----------------------------------------------------------------------------- model
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


def _parse(model_file: Path, package_dirs: list[Path], base_frame_rpy: list[float] | None):
    """(plant, context, prepared model, packages, YAML ``model:`` entry) of the model file."""
    from pydrake.multibody.parsing import Parser
    from pydrake.multibody.plant import MultibodyPlant

    from romoco_drake.robots.config import ModelSource
    from romoco_drake.robots.source import prepare_model

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
    return plant, plant.CreateDefaultContext(), prepared, packages, entry


def _geometry(model_file: Path, prepared, packages: dict[str, Path]) -> tuple[dict, dict]:
    """Per link, the vertices of its collision and of its visual shapes (link frame)."""
    from romoco_drake.robots.source import _resolve_uri

    def resolve(uri: str) -> Path:
        for scheme in ("package://", "model://"):
            package = uri[len(scheme):].partition("/")[0] if uri.startswith(scheme) else None
            if package is not None and package not in packages:
                raise RomocoError(f"{model_file}: {uri}: unknown package '{package}' "
                                  "(give its folder with --package-path)")
        return _resolve_uri(uri, packages, prepared.path)

    xml_root = ET.parse(prepared.path).getroot()
    return link_geometry(xml_root, "collision", resolve), link_geometry(xml_root, "visual", resolve)


def _soles(model_file: Path, tree: BodyTree, candidates: dict, R_WBase: np.ndarray, notes: list[str]):
    """(feet YAML entries, foot type, sole centres in world, whether both ankles sit at the front of
    their soles: the model's x axis then points backward)."""
    fwd_W, left_W = R_WBase[:, 0], R_WBase[:, 1]
    feet, types, centers, heel_first = {}, set(), {}, 0
    for side, (body, low, cloud, kind) in candidates.items():
        if kind != "collision":
            notes.append(f"feet.{side}: sole from {kind} (no collision geometry on '{body}'); check it")
        sole = cloud[cloud[:, 2] <= low + LOWEST_BAND]
        sl = np.column_stack([sole @ fwd_W, sole @ left_W])
        foot_type, outline = sole_outline(sl)
        types.add(foot_type)
        X = tree.X_WB[body]
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
    return feet, types.pop(), centers, heel_first == 2


def _joint_table(plant, prepared, all_moving: list, notes: list[str]) -> list[dict]:
    """Name, position limits, effort and velocity limits of every moving joint."""
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
    return joints


def infer(model_file: Path, name: str, package_dirs: list[Path] = (),
          base_frame_rpy: list[float] | None = None) -> Inferred:
    """Reads a biped's model file and infers the structural fields of its robot YAML.

    ``base_frame_rpy``: re-root the model at a frame so turned (ModelSource.base_frame_rpy); a
    URDF whose feet show it faces backward is re-rooted by a half turn about z.
    """
    plant, context, prepared, packages, entry = _parse(model_file, package_dirs, base_frame_rpy)
    notes: list[str] = []
    floating = [plant.get_body(i) for i in plant.GetFloatingBaseBodies()]
    if len(floating) != 1:
        raise RomocoError(f"{model_file}: expected one floating base body, found {len(floating)}")
    base = floating[0]
    geometry = _geometry(model_file, prepared, packages)
    tree = BodyTree.of(plant, context, base)
    R_WBase = tree.X_WB[base.name()].rotation().matrix()
    candidates = foot_candidates(model_file, tree, geometry, R_WBase[:, 1])
    legs, locked, all_moving = split_legs(tree, candidates, notes)
    feet, foot_type, centers, heel_first = _soles(model_file, tree, candidates, R_WBase, notes)
    if heel_first and base_frame_rpy is None and prepared.file_type == "urdf":
        # Both ankles sit at the front of their soles: the model's x axis points backward.
        turned = infer(model_file, name, package_dirs, base_frame_rpy=[0.0, 0.0, math.pi])
        turned.notes.insert(0, f"the model's root link '{base.name()}' faces backward (the ankles sit at "
                               "the front of the soles): re-rooted at an x-forward frame (base_frame_rpy)")
        return turned
    joints = _joint_table(plant, prepared, all_moving, notes)
    by_name = {j.name(): j for j in all_moving}
    knee_seed = knee_seeds(plant, context, legs, by_name, feet, R_WBase, notes)
    com = plant.CalcCenterOfMassPositionInWorld(context)
    ground = min(c[1] for c in candidates.values())
    hips = [by_name[js[0]].child_body().name() for js in legs.values() if js]
    leg_length = max(tree.X_WB[b].translation()[2] for b in hips) - ground if hips else com[2] - ground
    return Inferred(
        name=name, model=entry, base_body=base.name(), foot_type=foot_type, feet=feet,
        leg_joints=legs, locked_joints=locked, joints=joints, knee_seed=knee_seed,
        com_height_straight=float(com[2] - ground),
        foot_separation=float(abs((centers["left"] - centers["right"]) @ R_WBase[:, 1])),
        leg_length=float(leg_length), notes=notes)


# ----------------------------------------------------------------------------- YAML
def _vec(values) -> str:
    return "[" + ", ".join(f"{round(float(v), 4):g}" for v in values) + "]"


def _limit(value: float) -> str:
    return f"{value:.3f}" if math.isfinite(value) else "none"


def _reach(inf: Inferred, com_height: float, t_ss: float) -> str:
    """``walking.step_reach`` as YAML flow text: the straight leg is the hip's height over the
    ground in the model's zero pose, crouched in proportion to the CoM when standing."""
    b = step_reach(inf.leg_length, inf.leg_length * com_height / inf.com_height_straight,
                   inf.foot_separation, t_ss)
    return "{" + ", ".join(f"{f.name}: {getattr(b, f.name):g}" for f in dataclasses.fields(b)) + "}"


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
        "# guess: LIP walking at the nominal CoM height; t_ss = 1.15 sqrt(z0/g), swing 12 % of the leg;",
        "# step_reach (push recovery) from the leg's length and crouch (romoco_drake/robots/reach.py).",
        "walking:",
        f"  {{t_ss: {t_ss:g}, t_ds: 0.0, z0: {com_height:.3f}, step_width: {inf.foot_separation:.3f}, "
        f"swing_height: {swing:g},",
        f"   step_reach: {_reach(inf, com_height, t_ss)}}}",
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
