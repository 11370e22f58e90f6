"""The ``romoco`` command: list, show and run robots and scenarios."""

from __future__ import annotations

import argparse
import contextlib
import json
import select
import sys
from pathlib import Path

from romoco_drake.commands import output_dir, output_file
from romoco_drake.errors import RomocoError


def _cmd_list(args) -> int:
    from romoco_drake.control.registry import CONTROLLERS
    from romoco_drake.estimation.registry import ESTIMATORS
    from romoco_drake.planners.registry import PLANNERS
    from romoco_drake.robots.model import robot_names
    from romoco_drake.scenario import scenario_names

    registries = {"planners": PLANNERS, "controllers": CONTROLLERS, "estimators": ESTIMATORS}
    listing = {"robots": robot_names(), "scenarios": scenario_names()} | {
        key: list(registry) for key, registry in registries.items()}
    if args.json:
        print(json.dumps(listing))
        return 0
    for key, names in listing.items():
        print(f"{key}: {', '.join(names)}")
    for key, registry in registries.items():
        print(f"\n{key}:")
        for entry in registry.values():
            print(f"  {entry.name:14s} {entry.description}")
    return 0


def _robot_facts(robot) -> dict:
    return {
        "robot": robot.name,
        "description": robot.config.description,
        "mass_kg": round(robot.total_mass, 3),
        "dof": robot.nv,
        "joints": len(robot.joint_names),
        "actuators": robot.nu,
        "foot_type": robot.config.feet.type,
        "contact_points": {s: f.points.T.round(4).tolist() for s, f in robot.feet.items()},
        "internal_constraints": robot.num_internal_constraints(),
        "nominal_base_height_m": round(robot.nominal.base_height, 4),
        "nominal_com_m": robot.nominal.p_WCoM.round(4).tolist(),
    }


def _cmd_show(args) -> int:
    from pydrake.geometry import Meshcat
    from pydrake.multibody.meshcat import JointSliders
    from pydrake.systems.framework import DiagramBuilder

    from romoco_drake.interfaces.station import make_station
    from romoco_drake.robots.model import load_robot

    robot = load_robot(args.robot)
    facts = _robot_facts(robot)
    meshcat = Meshcat()
    builder = DiagramBuilder()
    station = builder.AddSystem(make_station(robot, meshcat=meshcat))
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant = station.GetSubsystemByName("plant")
    plant.SetPositions(plant.GetMyMutableContextFromRoot(context), robot.nominal.q)
    station.GetInputPort("actuation").FixValue(station.GetMyMutableContextFromRoot(context),
                                               [0.0] * robot.nu)
    diagram.ForcedPublish(context)
    sliders = JointSliders(meshcat, plant, initial_value=robot.nominal.q)
    if args.json:
        print(json.dumps(facts | {"meshcat_url": meshcat.web_url()}))
    else:
        print(f"{robot.name}: {facts['description']}")
        print(f"  mass {facts['mass_kg']} kg, {facts['dof']} DoF ({facts['joints']} joints + floating base), "
              f"{facts['actuators']} actuators, {facts['internal_constraints']} internal constraints")
        print(f"  nominal: base height {facts['nominal_base_height_m']} m, CoM {facts['nominal_com_m']} m")
        for side, pts in facts["contact_points"].items():
            print(f"  {side} {facts['foot_type']} foot ({robot.feet[side].body_name}): {pts}")
        print(f"  Meshcat: {meshcat.web_url()}")
    if not args.no_wait and sys.stdin.isatty():
        print("Move the page's joint sliders; press Enter to quit. ", end="", flush=True)
        with contextlib.suppress(KeyboardInterrupt):
            _follow_sliders(sliders, plant, diagram, context)
    return 0


def _follow_sliders(sliders, plant, diagram, context, period: float = 0.05) -> None:
    """Poses the robot as the page's joint sliders say until Enter is pressed."""
    import numpy as np

    sliders_context = sliders.CreateDefaultContext()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    shown = plant.GetPositions(plant_context).copy()
    while not select.select([sys.stdin], [], [], period)[0]:
        q = sliders.get_output_port().Eval(sliders_context)
        if not np.array_equal(q, shown):
            plant.SetPositions(plant_context, q)
            diagram.ForcedPublish(context)
            shown = q.copy()
    sys.stdin.readline()


def _cmd_diagram(args) -> int:
    from romoco_drake.diagram_export import write_diagram
    from romoco_drake.scenario import load_scenario

    out = output_file(args.out or Path(f"{Path(args.scenario).stem}.svg"), "--out")
    print(f"wrote {write_diagram(load_scenario(args.scenario), out, args.depth)}")
    return 0


def _cmd_new_robot(args) -> int:
    from romoco_drake.robots.onboard import model_file_path, new_robot

    if args.out.exists() and not args.force:
        raise RomocoError(f"--out {args.out}: exists (use --force to overwrite)")
    output_file(args.out, "--out")
    model = model_file_path(args.model_file, args.package_path)
    _, notes = new_robot(model, args.out, args.package_path)
    print(f"wrote {args.out}")
    for note in notes:
        print(f"  to check: {note}")
    name = args.out.stem
    print(f"next: `romoco show {name}`, then a scenario with `robot: {name}` (README: Adding a robot)")
    return 0


def _cmd_inertia_data(args) -> int:
    from romoco_drake.inertia.data import generate_dataset, save_dataset

    out = output_file(args.out or _default_inertia_data(args.robot), "--out")
    data = generate_dataset(args.robot, args.samples, seed=args.seed, points_per_motion=args.points,
                            progress=True)
    save_dataset(out, data)
    m = data["meta"]
    print(f"wrote {out}: {m['samples']} samples from {m['motions']} motions "
          f"({m['kept_fraction']:.1%} of {m['knots_tried']} IK knots kept) in {m['wall_s']} s")
    return 0


def _cmd_train_inertia(args) -> int:
    from romoco_drake.inertia.train import train_inertia
    from romoco_drake.robots.source import MODELS_DIR

    out = output_dir(args.out or MODELS_DIR / args.robot, "--out")
    s = train_inertia(args.robot, args.data or _default_inertia_data(args.robot), out, seed=args.seed)
    v, w = s["ccinn"]["validation"], s["wbo_integration"]
    print(f"wrote {out}/ccinn.npz, ccinn.yaml, wbo.npz, wbo.yaml in {s['wall_s']} s")
    print(f"  CCINN held-out relative Frobenius error: median {v['median']:.2%}, p99 {v['p99']:.2%} "
          f"({v['samples']} samples)")
    print(f"  WBO: integrated vs fitted max error {w['max_error_deg']['max']:.2f} deg (median "
          f"{w['max_error_deg']['median']:.2f}) over {w['motions']} held-out motions; max excursion "
          f"{w['max_excursion_deg']['max']:.1f} deg")
    return 0


def _default_inertia_data(robot: str) -> Path:
    return Path("out") / f"inertia_{robot}.npz"


def make_parser() -> argparse.ArgumentParser:
    from romoco_drake.bench import (
        agility,
        dropout,
        embedding,
        engines_cli,
        framework,
        inertia,
        push,
        realtime,
        rehearsal,
        report,
        rom,
        walking,
    )
    from romoco_drake.interfaces.lcm_log import register_plot
    from romoco_drake.runner import register_robot_sim, register_run

    parser = argparse.ArgumentParser(prog="romoco", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("list", help="robots, scenarios and components")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_cmd_list)
    p = sub.add_parser("show", help="open a robot in Meshcat and print its facts")
    p.add_argument("robot")
    p.add_argument("--json", action="store_true")
    p.add_argument("--no-wait", action="store_true", help="exit at once instead of serving the page")
    p.set_defaults(func=_cmd_show)
    register_run(sub)
    p = sub.add_parser("diagram", help="draw a scenario's wired Drake diagram (every system and port)")
    p.add_argument("scenario")
    p.add_argument("--out", type=Path, metavar="FILE.svg|.png|.pdf|.dot", help="default: SCENARIO.svg")
    p.add_argument("--depth", type=int, default=1, help="nested diagrams opened (1: the top level)")
    p.set_defaults(func=_cmd_diagram)
    _register_new_robot(sub)
    register_robot_sim(sub)
    register_plot(sub)
    bench = sub.add_parser("bench", help="benchmarks that print numbers").add_subparsers(
        dest="bench", required=True)
    for module in (rom, embedding, walking, engines_cli, agility, dropout, push, rehearsal):
        module.register(bench)
    walking.register_tick(bench)
    realtime.register(bench)
    framework.register(bench)
    inertia.register(bench)
    report.register(sub)
    _register_inertia(sub)
    return parser


def _register_new_robot(sub) -> None:
    p = sub.add_parser("new-robot", help="infer a robot YAML skeleton from a biped's URDF/SDFormat file")
    p.add_argument("model_file", metavar="MODEL_FILE",
                   help="a URDF/SDFormat path, or package://PKG/path (example-robot-data or --package-path)")
    p.add_argument("--package-path", type=Path, action="append", default=[], metavar="DIR",
                   help="a ROS package (folder with package.xml) or a folder of them, for package:// URIs")
    p.add_argument("--out", type=Path, required=True, metavar="robots/NAME.yaml",
                   help="the YAML to write; its file name is the robot's name")
    p.add_argument("--force", action="store_true", help="overwrite --out")
    p.set_defaults(func=_cmd_new_robot)


def _register_inertia(sub) -> None:
    """Centroidal inertia (issue 14): data generation and training (the benchmark: bench inertia)."""
    p = sub.add_parser("inertia-data", help="IK samples of foot poses -> centroidal inertia (CCINN data)")
    p.add_argument("robot")
    p.add_argument("--samples", type=int, default=20000, help="kept IK samples")
    p.add_argument("--out", type=Path, metavar="FILE.npz", help="default: out/inertia_ROBOT.npz")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--points", type=int, default=20, help="knots per sampled motion")
    p.set_defaults(func=_cmd_inertia_data)
    p = sub.add_parser("train-inertia", help="train the CCINN and fit the WBO map from inertia-data")
    p.add_argument("robot")
    p.add_argument("--data", type=Path, metavar="FILE.npz", help="default: out/inertia_ROBOT.npz")
    p.add_argument("--out", type=Path, metavar="DIR", help="default: models/ROBOT/")
    p.add_argument("--seed", type=int, default=0)
    p.set_defaults(func=_cmd_train_inertia)


def main(argv: list[str] | None = None) -> int:
    args = make_parser().parse_args(argv)
    try:
        from romoco_drake.registry import load_plugins

        load_plugins()
        return args.func(args)
    except RomocoError as e:
        print(f"romoco: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("romoco: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
