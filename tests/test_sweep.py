"""The sweep runner: rows in order, the same in process and on Ray, and one-line errors."""

import subprocess
import sys

import pytest

from romoco_drake.bench import sweep
from romoco_drake.bench.sweep import SweepOptions, Variant, run_sweep
from romoco_drake.bench.walking import bench_matrix
from romoco_drake.errors import RomocoError
from romoco_drake.scenario import load_scenario

TIMING = ("realtime_factor", "controller_tick_ms")  # wall-clock numbers, the only ones that may differ


def echo_job(scenario, scale):
    return {"name": scenario.name, "scaled": scale * scenario.duration_s}


def test_in_process_rows_keep_order_params_and_report_progress():
    base = load_scenario("g1_stand")
    variants = [Variant(base, {"i": i}, echo_job, {"scale": i}) for i in range(3)]
    lines = []
    rows = run_sweep(variants, progress=lines.append)
    assert rows == [{"i": i, "name": "g1_stand", "scaled": i * base.duration_s} for i in range(3)]
    assert [line.split("]")[1].split("|")[0].strip() for line in lines] == [
        "1/3 done, 2 left, ETA 0m00s", "2/3 done, 1 left, ETA 0m00s", "3/3 done, 0 left, ETA 0m00s"]
    assert run_sweep([]) == []


@pytest.mark.parametrize("workers", [0, -1, 2.5])
def test_bad_worker_counts(workers):
    with pytest.raises(RomocoError, match="--workers must be an integer"):
        SweepOptions(workers)


@pytest.mark.parametrize("address, message", [("nohost", "is not host:port"), ("h:xx", "is not host:port"),
                                              ("127.0.0.1:1", "no Ray cluster reachable")])
def test_bad_ray_addresses(address, message):
    with pytest.raises(RomocoError, match=message):
        SweepOptions(address=address)


def test_missing_ray_is_one_line(monkeypatch):
    monkeypatch.setattr(sweep.importlib.util, "find_spec", lambda name: None)
    assert not SweepOptions(1).uses_ray  # in process needs no Ray
    with pytest.raises(RomocoError, match=r"need Ray, which is not installed: pip install -e '\.\[ray\]'"):
        SweepOptions(2)


@pytest.mark.parametrize("args", [["bench", "matrix", "--workers", "0"],
                                  ["bench", "agility", "--ray-address", "127.0.0.1:1"],
                                  ["reproduce", "nature"], ["reproduce", "all", "--workers", "0"]])
def test_cli_sweep_errors_exit_2_in_one_line(args):
    out = subprocess.run([sys.executable, "-m", "romoco_drake.cli", *args], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 2
    assert out.stderr.startswith("romoco: error: ") and len(out.stderr.strip().splitlines()) == 1


@pytest.fixture
def local_ray(ray_alone):
    ray = pytest.importorskip("ray")
    yield ray
    ray.shutdown()
    sweep._started.clear()


@pytest.mark.slow
def test_ray_matrix_equals_in_process_matrix(local_ray):
    """The issue's test: a matrix on 2 local Ray workers gives the rows of --workers 1 (2 runs,
    one a worker, so that the rows come back in the matrix's order whichever finishes first)."""
    cells = (["g1"], ["hlip", "dcm"], ["tscqp"], 2.0)
    alone = bench_matrix(*cells)
    on_ray = bench_matrix(*cells, sweep=SweepOptions(workers=2))
    assert [(r["planner"], r["controller"]) for r in alone] == [("hlip", "tscqp"), ("dcm", "tscqp")]
    strip = [[{k: v for k, v in r.items() if k not in TIMING} for r in rows] for rows in (alone, on_ray)]
    assert strip[0] == strip[1]
    assert all(r["steps"] > 0 and not r["fell"] for r in alone)
    # The instance started stays up for the next sweep with the same options (bench push's rounds).
    assert sweep._started == [SweepOptions(workers=2)] and local_ray.is_initialized()
    assert sweep._ray_for(SweepOptions(workers=2)) is local_ray and local_ray.cluster_resources()["CPU"] == 2
