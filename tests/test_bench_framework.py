"""`romoco bench framework`: every kind's diagram runs its callbacks once a period, and the CLI
prints the table."""

import json

from romoco_drake.bench.framework import KINDS, SYSTEMS, bench_framework
from romoco_drake.cli import main


def test_each_kind_fires_once_per_period_on_every_system():
    ticks = 20
    r = bench_framework(ticks)
    assert list(r["kinds"]) == list(KINDS)
    for kind, row in r["kinds"].items():
        # A periodic publish also fires once at initialization; updates and port reads do not.
        extra = SYSTEMS if kind == "publish" else 0
        assert row["callbacks"] == SYSTEMS * ticks + extra, kind
        assert row["us_per_system_tick"] > 0.0, kind
    assert r["reference_us"] > 0.0


def test_cli_prints_every_kind(capsys):
    assert main(["bench", "framework", "--ticks", "5"]) == 0
    text = capsys.readouterr().out
    assert all(kind in text for kind in KINDS)
    assert main(["bench", "framework", "--ticks", "5", "--json"]) == 0
    assert set(json.loads(capsys.readouterr().out.splitlines()[-1])["kinds"]) == set(KINDS)
