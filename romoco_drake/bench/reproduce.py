"""``romoco reproduce``: each paper's claims rerun on our robots, beside the paper's numbers.

Every run of every requested paper goes into one sweep (:mod:`~romoco_drake.bench.sweep`), so
``--workers``/``--ray-address`` spread them all; the claims are then scored from the rows. A
claim is one row: what the paper reports, what we measured, the ratio or direction, and whether
it holds by the rule written beside it (the paper's own threshold wherever it states one; ours,
fixed before the first run, where it does not). A fall fails every claim its run is part of,
except the claims that a run falls (ALIP's instability; ID falling where QP does not).

- **romoco** (:data:`REFERENCES`): Fig. 7, the four whole-body controllers under the paper's DCM
  planner on Cassie, as the paper ran it, with G1 and H1 beside it; the IK controllers with
  eq. 17's gravity feedforward; the output groups of eq. 13; ID's sensitivity to a model error
  (an unmodelled payload); Fig. 8, the four planners on Cassie at T_DS = 0 with each law's
  allowed gains (ALIP deadbeat and α-converging, H-LIP deadbeat and LQR); Fig. 9, G1 stepping in
  place under DCM + POS-IK.
- **xo**: the Table I walk: Figs. 5-9 and the centroidal/contact angular momentum ratio.
- **vimpc**: the agility table (bench agility's ramps, scored on ``settled``), the MPC solve time
  (bench tick), the CCINN's inertia against the plant's along the MPC horizon (Fig. 3), torso
  vs whole-body orientation on the 0.9 m/s, 0.9 rad/s circle (Fig. 6) and step lengths.

``quick`` (:data:`QUICK`) shortens what :data:`QUICK_SHORTENS` says. Each paper's runs and claims
are in its module: ``reproduce_romoco``, ``reproduce_xo``, ``reproduce_vimpc``.
"""

from __future__ import annotations

from collections.abc import Callable

from romoco_drake.bench.agility import MOTIONS
from romoco_drake.bench.reproduce_claims import Claim, Settings
from romoco_drake.bench.reproduce_romoco import FIG7_ROBOTS, romoco_claims, romoco_variants
from romoco_drake.bench.reproduce_vimpc import vimpc_claims, vimpc_variants
from romoco_drake.bench.reproduce_xo import xo_claims, xo_variants
from romoco_drake.bench.sweep import SweepOptions, Variant, run_sweep
from romoco_drake.errors import RomocoError

PAPERS = ("romoco", "xo", "vimpc")
# Each paper, typed once: authors, title, venue, year, arXiv id.
REFERENCES = {
    "romoco": "M. Dai and A. D. Ames, \"RoMoCo: Robotic Motion Control Toolbox for Reduced-Order "
              "Model-Based Locomotion on Bipedal and Humanoid Robots\", preprint, 2025, arXiv:2509.19545.",
    "xo": "V. C. Paredes, D. A. Hagen, S. W. Chesebrough, R. Swann, D. Garagić and A. Hereid, \"Moving past "
          "point-contacts: Extending the ALIP model to humanoids with non-trivial feet using hierarchical, "
          "full-body momentum control\", American Control Conference (ACC), 2024, arXiv:2408.05308.",
    "vimpc": "S. H. Bang, J. Lee, C. Gonzalez and L. Sentis, \"Variable Inertia Model Predictive Control for "
             "Fast Bipedal Maneuvers\", preprint, 2024, arXiv:2407.16811.",
}
FULL = Settings(FIG7_ROBOTS, None, 10.0, 10.0, None, tuple(MOTIONS), 0.1, (0.08, 0.125), (1.0, 1.15), 2000,
                12.0)
QUICK = Settings(("cassie",), 6.0, 7.0, 6.0, 10.0, ("forward",), 0.5, (), (), 200, None)
QUICK_SHORTENS = ("Fig. 7 on Cassie only, first 6 s of its profile, without the IK runs under our own "
                  "feedforward; Fig. 8 7 s instead of 10 s; Fig. 9 6 s instead of 10 s; the XO walk its "
                  "first 10 s (0.225, 0.45 m/s forward) of 44 s; agility the forward ramp only, at 0.5 "
                  "instead of 0.1 (m/s)/s, and no ramps at other rates to pair the inertia modes over; "
                  "solve time over 200 instead of 2000 ticks; no Fig. 6 circle")

SECTIONS: dict[str, tuple[Callable[[Settings], list[Variant]], Callable[[list[dict]], list[Claim]]]] = {
    "romoco": (romoco_variants, romoco_claims), "xo": (xo_variants, xo_claims),
    "vimpc": (vimpc_variants, vimpc_claims)}


def reproduce(papers: list[str], quick: bool = False, sweep: SweepOptions | None = None, progress=None
              ) -> tuple[list[Claim], list[dict]]:
    """The claims of ``papers`` and the rows of their runs (one sweep for all)."""
    unknown = [p for p in papers if p not in PAPERS]
    if unknown:
        raise RomocoError(f"unknown paper '{unknown[0]}' (known: {', '.join(PAPERS)}, all)")
    settings = QUICK if quick else FULL
    variants = [v for p in papers for v in SECTIONS[p][0](settings)]
    # The longest runs first, so the last ones to finish are short (the workers end together).
    order = sorted(range(len(variants)), key=lambda i: -_length(variants[i]))
    done = run_sweep([variants[i] for i in order], sweep, progress)
    rows: list[dict] = [{}] * len(variants)
    for i, row in zip(order, done, strict=True):
        rows[i] = row
    claims = [c for p in papers for c in SECTIONS[p][1]([r for r in rows if _paper(r) == p])]
    return claims, rows


def _paper(row: dict) -> str:
    romoco = ("fig7", "fig7_ours", "model_error", "fig8", "fig9")
    return "romoco" if row["part"] in romoco else "xo" if row["part"] == "xo" else "vimpc"


def _length(variant: Variant) -> float:
    """Simulated seconds of a variant, times its robot's rough cost per simulated second."""
    duration = variant.options.get("duration") or variant.scenario.duration_s
    return duration * {"draco": 3.0, "xo": 2.0}.get(variant.scenario.robot, 1.5)
