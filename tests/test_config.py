"""Bad input: every config mistake is a one-line error naming the file and the key."""

import shutil

import pytest
import yaml

from romoco_drake.config import load_yaml_file
from romoco_drake.control.registry import CONTROLLERS
from romoco_drake.control.settings import ControllerSettings
from romoco_drake.errors import ConfigError, RomocoError
from romoco_drake.estimation.registry import ESTIMATORS
from romoco_drake.planners.settings import FootPlacementConfig
from romoco_drake.robots.model import RobotModel, load_robot_config_file
from romoco_drake.robots.source import ROBOTS_DIR
from romoco_drake.scenario import Scenario, load_scenario, validate_scenario, with_overrides
from romoco_drake.wiring import build_diagram


def _write(tmp_path, name, data):
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


_HOLD = {"kp": 50.0, "kd": 14.0, "weight": 0.1}  # a locked_hold.recovery


def _scenario(**overrides):
    data = {"robot": "g1", "duration_s": 1.0, "controller": {"name": "standing", "rate_hz": 500.0}}
    data.update(overrides)
    return data


def test_step_adaptation_without_a_reach_is_a_load_error(tmp_path, monkeypatch):
    """Step adaptation is on by default: a robot YAML without ``walking.step_reach`` cannot do it,
    and says so at load time instead of walking unadapted."""
    robots = tmp_path / "robots"
    robots.mkdir()
    data = yaml.safe_load((ROBOTS_DIR / "g1.yaml").read_text())
    del data["walking"]["step_reach"]
    data["name"] = "g1_noreach"
    (robots / "g1_noreach.yaml").write_text(yaml.safe_dump(data))
    monkeypatch.setenv("ROMOCO_ROBOT_PATH", str(robots))
    path = _write(tmp_path, "bad", _scenario(robot="g1_noreach", planner={"name": "hlip"}))
    with pytest.raises(ConfigError, match=r"planner.step_adaptation.enabled: robot 'g1_noreach' has no "
                                          r"walking.step_reach") as info:
        load_scenario(str(path))
    assert "\n" not in str(info.value)
    off = _write(tmp_path, "off", _scenario(robot="g1_noreach",
                                            planner={"name": "hlip", "step_adaptation": {"enabled": False}}))
    assert not load_scenario(str(off)).planner.step_adaptation.enabled


def test_a_walking_height_no_pose_reaches_is_a_one_line_error(tmp_path, monkeypatch):
    """walking.z0 above what G1's legs reach (2.0 m against 0.65 m standing) walked it into a fall
    at 0.48 s; building the walking loop now says why, naming the file and key."""
    robots = tmp_path / "robots"
    robots.mkdir()
    data = yaml.safe_load((ROBOTS_DIR / "g1.yaml").read_text())
    data["walking"]["z0"], data["name"] = 2.0, "g1_tall"
    (robots / "g1_tall.yaml").write_text(yaml.safe_dump(data))
    monkeypatch.setenv("ROMOCO_ROBOT_PATH", str(robots))
    path = _write(tmp_path, "tall", _scenario(robot="g1_tall", controller={"name": "tscqp"},
                                              planner={"name": "hlip"}))
    scenario = load_scenario(str(path))
    with pytest.raises(RomocoError) as info:
        build_diagram(scenario)
    message = str(info.value)
    assert "\n" not in message and f"{robots / 'g1_tall.yaml'}: walking.z0: no standing pose" in message
    assert "the nominal pose stands at 0.65 m" in message


@pytest.mark.parametrize(
    "data, key, words",
    [
        (_scenario(robot="atlas"), "robot", "unknown robot 'atlas'"),
        (_scenario(duraton_s=2.0), "duraton_s", "unknown key"),
        (_scenario(controller={"name": "standing", "rate": 1.0}), "controller.rate",
         "controller 'standing' has no setting 'rate' (its keys: name, rate_hz)"),
        (_scenario(controller={"name": "id", "angular_momentum": {"weight": 1.0}}),
         "controller.angular_momentum",
         "controller 'id' has no setting 'angular_momentum' (its keys: name, rate_hz, load_split_weight"),
        (_scenario(controller={"name": "tscqp", "angular_momentum": {"weigth": 1.0}}),
         "controller.angular_momentum.weigth", "unknown key"),
        (_scenario(controller={"name": "momentum", "gains": {"kp": -1.0}}), "controller.gains.kp",
         "must be in"),
        (_scenario(planner={"name": "vimpc", "gain": "lqr"}), "planner.gain",
         "planner 'vimpc' has no setting"),
        (_scenario(planner={"name": "vimpc", "knots": 100}), "planner.knots", "must be in [1, 30]"),
        (_scenario(vimpc={"inertia": "network"}), "vimpc", "unknown key"),
        (_scenario(robot="bolt", controller={"name": "tscqp", "ankle": {"gain": 0.1}}),
         "controller.ankle.gain", "robot 'bolt' has point feet"),
        (_scenario(controller={"name": "tscqp", "angular_momentum": {"weight": 30.0, "when": "recovering"}},
                   planner={"name": "hlip", "step_adaptation": {"enabled": False}}),
         "controller.angular_momentum.when", "'recovering' needs the planner's step adaptation"),
        (_scenario(controller={"name": "tscqp", "angular_momentum": {"weight": 3.0, "target": "mpc"}}),
         "controller.angular_momentum.target", "'mpc' needs a wrench MPC's plan"),
        (_scenario(controller={"name": "tscqp", "locked_hold": {"kp": -1.0}}), "controller.locked_hold.kp",
         "must be in"),
        (_scenario(controller={"name": "tscqp", "locked_hold": {"recovery": {**_HOLD, "weight": -1.0}},
                               "angular_momentum": {"weight": 30.0}}, planner={"name": "hlip"}),
         "controller.locked_hold.recovery.weight", "must be in"),
        (_scenario(controller={"name": "tscqp", "locked_hold": {"recovery": {"kp": 50.0, "kd": 14.0}}}),
         "controller.locked_hold.recovery.weight", "missing required key"),
        (_scenario(controller={"name": "tscqp", "locked_hold": {"recovery": _HOLD},
                               "angular_momentum": {"weight": 30.0}},
                   planner={"name": "hlip", "step_adaptation": {"enabled": False}}),
         "controller.locked_hold.recovery", "needs the planner's step adaptation"),
        (_scenario(controller={"name": "tscqp", "locked_hold": {"recovery": _HOLD}},
                   planner={"name": "hlip"}),
         "controller.locked_hold.recovery", "needs the angular-momentum term"),
        (_scenario(robot="cassie", planner={"name": "hlip"},
                   controller={"name": "tscqp", "locked_hold": {"recovery": _HOLD},
                               "angular_momentum": {"weight": 30.0}}),
         "controller.locked_hold.recovery", "robot 'cassie' has no locked joints to loosen"),
        (_scenario(controller={"name": "mpc"}), "controller.name", "unknown controller 'mpc'"),
        (_scenario(planner={"name": "lipm"}), "planner.name", "unknown planner 'lipm' (known: alip, hlip"),
        (_scenario(planner={"name": "alip_general", "gain": "lqr"}), "planner.gain", "supports gains"),
        (_scenario(estimator={"name": "ekf"}), "estimator.name", "unknown estimator 'ekf'"),
        (_scenario(estimator={"name": "kalman"}, sensors={"orientation_output": False}),
         "sensors.orientation_output", "the kalman estimator takes the IMU's orientation"),
        (_scenario(sensors={"contact_debounce_s": -0.001}), "sensors.contact_debounce_s", "must be in"),
        (_scenario(sensors={"gyro_bias_walk": -1.0}), "sensors.gyro_bias_walk", "must be in"),
        (_scenario(controller={"name": "tscqp", "solver": "osqp"}), "controller.solver", "not one of: daqp"),
        (_scenario(controller={"name": "id", "solver": "clarabel"}), "controller.solver",
         "controller 'id' has no setting 'solver'"),
        (_scenario(duration_s="long"), "duration_s", "expected a number"),
        (_scenario(duration_s=-1.0), "duration_s", "must be positive"),
        ({"duration_s": 1.0}, "robot", "missing required key"),
    ],
)
def test_bad_scenario_names_file_and_key(tmp_path, data, key, words):
    path = _write(tmp_path, "bad", data)
    with pytest.raises(ConfigError) as info:
        load_scenario(str(path))
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith(str(path)) and f": {key}: " in message and words in message


def test_scenario_built_in_python_is_validated_like_yaml():
    """build_diagram checks a Scenario made in code against the same registries."""
    scenario = Scenario(robot="g1", controller=ControllerSettings(name="mpc"))
    with pytest.raises(ConfigError, match=r"^<scenario g1>: controller.name: unknown controller 'mpc'"):
        build_diagram(scenario)
    scenario = Scenario(robot="g1", planner=FootPlacementConfig(name="lipm"))
    with pytest.raises(ConfigError, match=r"planner.name: unknown planner 'lipm'"):
        validate_scenario(scenario)
    # The settings must be the chosen component's own: a bare ControllerSettings has no TSC-QP terms.
    scenario = Scenario(robot="g1", controller=ControllerSettings(name="tscqp"))
    with pytest.raises(ConfigError, match=r"controller: controller 'tscqp' takes TscqpConfig settings"):
        validate_scenario(scenario)


def test_every_registered_component_is_listed_and_buildable():
    """romoco list, the overrides and validation read one registry per kind."""
    assert list(CONTROLLERS) == ["standing", "tscqp", "id", "velik", "posik", "momentum", "wbc"]
    assert list(ESTIMATORS) == ["ground_truth", "kalman", "invariant_ekf"]
    for name in CONTROLLERS:
        validate_scenario(with_overrides(Scenario(robot="g1"), controller=name))
    with pytest.raises(RomocoError, match="unknown controller 'mpc'"):
        with_overrides(Scenario(robot="g1"), controller="mpc")
    with pytest.raises(RomocoError, match="unknown QP solver 'osqp'"):
        with_overrides(Scenario(robot="g1"), solver="osqp")
    with pytest.raises(RomocoError, match="controller 'standing' solves no QP"):
        with_overrides(Scenario(robot="g1"), solver="clarabel")


def test_switching_component_keeps_shared_settings():
    """--controller wbc on a TSC-QP scenario keeps its rate and terms; --controller id drops them."""
    tscqp = with_overrides(load_scenario("g1_walk", ["push_recovery"]), controller="wbc").controller
    assert tscqp.name == "wbc" and tscqp.rate_hz == 500.0 and tscqp.angular_momentum.weight == 30.0
    ident = with_overrides(load_scenario("g1_walk", ["push_recovery"]), controller="id").controller
    assert ident.name == "id" and ident.rate_hz == 500.0 and not hasattr(ident, "angular_momentum")


def test_unknown_scenario_name():
    with pytest.raises(RomocoError, match="unknown scenario 'nope'"):
        load_scenario("nope")


def test_malformed_yaml(tmp_path):
    path = tmp_path / "broken.yaml"
    path.write_text("robot: [g1\n")
    with pytest.raises(ConfigError, match="invalid YAML at line"):
        load_scenario(str(path))


def test_exponents_without_a_dot_are_numbers(tmp_path):
    """YAML 1.2 reads 1e-3 as a number; PyYAML (YAML 1.1) alone read it as text."""
    path = tmp_path / "exponents.yaml"
    path.write_text("robot: g1\ntime_step: 1e-3\nduration_s: 2E+1\n")
    assert load_yaml_file(path) == {"robot": "g1", "time_step": 0.001, "duration_s": 20.0}
    (tmp_path / "text.yaml").write_text("a: 1e5x\nb: 1.5e3\n")
    assert load_yaml_file(tmp_path / "text.yaml") == {"a": "1e5x", "b": 1500.0}
    scenario = load_scenario(str(path))
    assert scenario.time_step == 0.001 and scenario.duration_s == 20.0


def _robot_data():
    return yaml.safe_load((ROBOTS_DIR / "g1.yaml").read_text())


@pytest.mark.parametrize(
    "edit, key",
    [
        (lambda d: d["feet"]["left"].update(bodyy="x"), "feet.left.bodyy"),
        (lambda d: d["feet"]["left"].update(body="no_such_link"), "feet.left.body"),
        (lambda d: d.update(locked_joints=["no_such_joint"]), "locked_joints"),
        (lambda d: d["feet"]["left"].update(points=[[0, 0, 0]]), "feet.left.points"),
        (lambda d: d.pop("walking"), "walking"),
        (lambda d: d.update(gains=[{"joints": "*hip*", "kp": 1.0, "kd": 0.1}]), "gains"),
        (lambda d: d["nominal"].update(com_height="high"), "nominal.com_height"),
        (lambda d: d["walking"].update(command_limits={"ax": -1.0}), "walking.command_limits"),
        (lambda d: d["walking"].update(command_limits={"vz": 1.0}), "walking.command_limits.vz"),
    ],
)
def test_bad_robot_yaml_names_file_and_key(tmp_path, edit, key):
    data = _robot_data()
    edit(data)
    path = _write(tmp_path, "g1", data)
    with pytest.raises(ConfigError) as info:
        RobotModel(load_robot_config_file(path), path)
    assert f"{path}: {key}" in str(info.value)


def test_unreadable_model_file(tmp_path):
    data = _robot_data()
    data["model"] = {"package": "romoco_models", "file": "missing/robot.urdf"}
    path = _write(tmp_path, "g1", data)
    with pytest.raises(RomocoError, match="robot.urdf: cannot read model file"):
        RobotModel(load_robot_config_file(path), path)


def test_malformed_model_file(tmp_path, monkeypatch):
    models = tmp_path / "models"
    shutil.copytree(ROBOTS_DIR.parent / "models", models)
    (models / "h1" / "h1.urdf").write_text("<robot name='h1'><link name='pelvis'>")
    monkeypatch.setattr("romoco_drake.robots.source.MODELS_DIR", models)
    from romoco_drake.robots.source import _prepare_cached

    _prepare_cached.cache_clear()
    data = yaml.safe_load((ROBOTS_DIR / "h1.yaml").read_text())
    path = _write(tmp_path, "h1", data)
    try:
        with pytest.raises(RomocoError, match="h1.urdf: malformed XML"):
            RobotModel(load_robot_config_file(path), path)
    finally:
        _prepare_cached.cache_clear()


def test_robot_name_must_match_file(tmp_path):
    data = _robot_data()
    path = _write(tmp_path, "other", data)
    with pytest.raises(ConfigError, match="does not match the file name"):
        load_robot_config_file(path)
