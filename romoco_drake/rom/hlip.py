"""H-LIP: LIP single support plus constant-momentum double support (RoMoCo §III-B, eq. 4-7)."""

from __future__ import annotations

from romoco_drake.rom.lip import IMPACT_B, ds_flow, ss_flow
from romoco_drake.rom.s2s import StepToStep
from romoco_drake.spatial import GRAVITY


def hlip_s2s(z0: float, t_ss: float, t_ds: float, g: float = GRAVITY) -> StepToStep:
    """The H-LIP S2S map x⁻_{k+1} = A^H x⁻_k + B^H u_k of eq. 5-6.

    Eq. 6 prints A^H = exp(A_SS T_SS + A_DS T_DS); A_SS and A_DS do not commute, so the map of
    eq. 5 is the product exp(A_SS T_SS) exp(A_DS T_DS), which is what is used here.
    """
    flow_ss = ss_flow(t_ss, z0, g)
    return StepToStep(A=flow_ss @ ds_flow(t_ds, z0), B=flow_ss @ IMPACT_B)
