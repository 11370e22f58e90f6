"""Foot contact: holonomic contact rows, point-force → wrench map, friction and CoP limits.

A foot in contact is held by a few representative sole points (paper Fig. 5): toe and
heel for a line foot; front-left (LF), front-right (RF) and mid-back (MB) for a plane
foot. Their stacked world-frame translational constraints (3 rows a point) fix 5 (line)
or 6 (plane) foot DoF; the rows are redundant (rank 5 of 6, rank 6 of 9), as in the paper.
A point foot is its one point: 3 independent rows, the foot free to turn about it.

The multipliers of those rows are point forces f (3 a point, expressed in world). They
act on the robot only through their resultant wrench about the sole centroid,
Σ J_iᵀ f_i = J_footᵀ [m; f], so the friction and CoP limits are imposed on that wrench
(net friction pyramid, net normal force, CoP inside the whole sole polygon, yaw moment
within torsional friction) and mapped back to the point forces: the split among the points
(internal forces) is free, and the CoP may use the whole sole, not only the triangle of the
representative points. A point foot's force carries no moment, so it has no CoP or torsion
limit: only the friction pyramid and the unilateral normal force.

Limits are expressed in the foot's sole frame S (:func:`~romoco_drake.embedding.outputs.sole_frame`:
origin at the sole-point centroid, z_S the sole normal, x_S forward), so they hold when the
foot is not level. A point foot's limits are in its yaw frame instead (world z up, x along the
base's heading: :func:`~romoco_drake.embedding.outputs.point_foot_yaw`), as its body tilts with
the leg.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pydrake.multibody.tree import Frame

from romoco_drake.embedding.outputs import Output, point_foot_yaw, sole_frame
from romoco_drake.errors import RomocoError
from romoco_drake.robots.kinematics import RobotKinematics
from romoco_drake.robots.model import RobotModel
from romoco_drake.rom.polygon import convex_hull_2d
from romoco_drake.spatial import skew, wrench_map

SIDES = ("left", "right")
# Contact domain -> feet in contact.
DOMAINS = {"left": ("left",), "right": ("right",), "double": ("left", "right"), "none": ()}


def select_contact_points(robot: RobotModel, side: str, line: bool | None = None
                          ) -> tuple[tuple[str, ...], np.ndarray]:
    """Names and positions p_FC (3×k, foot frame) of the representative contact points.

    Line foot: the toe and heel points. Plane foot: LF and RF are the left- and right-most of
    the front points, MB the mean of the back points ("front"/"back": within 10% of the sole
    length from the front-/back-most point along the forward axis). ``line=True`` models a
    plane foot as the line from the mean of its back points to the mean of its front points.
    Point foot: its one point.
    """
    pts = robot.feet[side].points
    if robot.is_point_foot:
        return ("point",), pts[:, :1].copy()
    if robot.is_line_foot:
        return ("toe", "heel"), pts[:, :2].copy()
    R_FS, p_FS = sole_frame(robot, side)
    x, y = (R_FS.T @ (pts - p_FS[:, None]))[:2]
    tol = 0.1 * (x.max() - x.min())
    front = np.flatnonzero(x >= x.max() - tol)
    back = x <= x.min() + tol
    if line:
        return ("toe", "heel"), np.column_stack([pts[:, front].mean(axis=1), pts[:, back].mean(axis=1)])
    lf, rf = front[np.argmax(y[front])], front[np.argmin(y[front])]
    chosen = np.column_stack([pts[:, lf], pts[:, rf], pts[:, back].mean(axis=1)])
    a, b, c = (R_FS.T @ chosen)[:2].T
    area = 0.5 * abs((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))
    if area < 1e-6:
        raise RomocoError(f"{robot.yaml_path}: feet.{side}.points: no non-collinear front-left, "
                          "front-right and mid-back points (a plane foot needs two front corners)")
    return ("lf", "rf", "mb"), chosen


def contact_frame(robot: RobotModel, kin: RobotKinematics, side: str) -> tuple[np.ndarray, float]:
    """The stance contact frame {c} of the XO paper (Fig. 1): origin p_Wc and heading ψ.

    The origin is the stance sole's centre (the centroid of its sole points); z is world up and
    x the stance foot's heading, the direction the CoM walks in this step (the embedding turns
    each swing foot to the planned heading before it lands). No-slip keeps {c} fixed over the
    step, so momenta about it evolve as the ALIP model says. A point foot's x is the base's
    heading (:func:`~romoco_drake.embedding.outputs.point_foot_yaw`).
    """
    R_FS, p_FS = sole_frame(robot, side)
    R_WF, p_WF = kin.frame_pose(robot.foot_frames[side])
    fx, fy, _ = (kin.R_base[:, 0] if robot.is_point_foot else R_WF @ R_FS[:, 0]).tolist()
    return R_WF @ p_FS + p_WF, math.atan2(fy, fx)


def contact_frame_state(kin: RobotKinematics, origin: np.ndarray, heading: float) -> np.ndarray:
    """[p (3); L_c (3)] in {c}: CoM minus the origin, and the angular momentum about the origin."""
    c, s = math.cos(heading), math.sin(heading)
    px, py, pz = (kin.p_com - origin).tolist()
    Lx, Ly, Lz = kin.angular_momentum_about(origin).tolist()
    return np.array([c * px + s * py, c * py - s * px, pz, c * Lx + s * Ly, c * Ly - s * Lx, Lz])


def support_halfplanes(robot: RobotModel, side: str, line: bool | None = None
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Outward normals N (e×2) and offsets d (e,) with the sole region {c : N c ≤ d} in S (x, y).

    Plane foot: the edges of the convex hull of all sole points. Line foot (or ``line=True``):
    the segment from heel to toe along x_S (its lateral CoP is zero by construction). Point
    foot: none (its force has no moment, so no CoP to bound).
    """
    if robot.is_point_foot:
        return np.zeros((0, 2)), np.zeros(0)
    R_FS, p_FS = sole_frame(robot, side)
    if robot.is_line_foot or line:
        _, points = select_contact_points(robot, side, line)
        toe, heel = (R_FS.T @ (points - p_FS[:, None]))[0]
        return np.array([[1.0, 0.0], [-1.0, 0.0]]), np.array([toe, -heel])
    hull = convex_hull_2d((R_FS.T @ (robot.feet[side].points - p_FS[:, None]))[:2].T)
    edges = np.roll(hull, -1, axis=0) - hull
    normals = np.column_stack([edges[:, 1], -edges[:, 0]]) / np.linalg.norm(edges, axis=1)[:, None]
    return normals, np.einsum("ij,ij->i", normals, hull)


@dataclass(frozen=True)
class FootContact:
    """One foot's contact model, all constant in the foot's sole frame S.

    ``wrench_map`` maps the stacked point forces (in S) to the wrench [f; m] in S about the
    sole centroid; ``A_S f_S ≤ b`` are its friction/CoP limits on point forces in S.
    """

    side: str
    frame: Frame
    point_names: tuple[str, ...]
    points_F: np.ndarray  # 3×k representative contact points in the foot frame
    R_FS: np.ndarray
    p_FS: np.ndarray
    wrench_map: np.ndarray  # 6 × 3k
    A_S: np.ndarray
    b: np.ndarray
    motion_basis: np.ndarray  # 3k × r orthonormal: the point velocities a rigid foot can have, in S
    offsets_F: np.ndarray  # 3×k: the contact points relative to the sole centroid, foot frame
    # The torsion rows' change per metre the CoP is moved off the centroid (2 × 3k; none for a point
    # foot), and the radius ρ of the torsion limit, beyond which a shift takes no more.
    torsion_per_shift: np.ndarray
    torsion_radius: float


def _foot_contact(robot: RobotModel, side: str, line_contact: bool, friction_margin: float, cop_margin: float,
                  min_normal_force: float) -> FootContact:
    """One foot's contact points, wrench map, force limits and motion basis (see :class:`ContactModel`)."""
    mu = robot.config.feet.friction * (1.0 - friction_margin)
    limits = np.array([
        [0.0, 0.0, -1.0, 0.0, 0.0, 0.0],
        [1.0, 0.0, -mu, 0.0, 0.0, 0.0],
        [-1.0, 0.0, -mu, 0.0, 0.0, 0.0],
        [0.0, 1.0, -mu, 0.0, 0.0, 0.0],
        [0.0, -1.0, -mu, 0.0, 0.0, 0.0],
    ])
    names, points_F = select_contact_points(robot, side, line_contact)
    R_FS, p_FS = sole_frame(robot, side)
    sole_z = R_FS[:, 2] @ (robot.feet[side].points - p_FS[:, None])
    if np.max(np.abs(sole_z)) > 1e-3:
        raise RomocoError(f"{robot.yaml_path}: feet.{side}.points: not in one plane normal to "
                          f"'up' (offsets {np.round(sole_z, 4).tolist()} m)")
    G = wrench_map(R_FS.T @ (points_F - p_FS[:, None]))
    N, d = support_halfplanes(robot, side, line_contact)
    # N·(−m_y, m_x) ≤ (d − margin) f_z, valid for f_z ≥ 0.
    cop = np.zeros((len(d), 6))
    cop[:, 2] = -(d - cop_margin)
    cop[:, 3] = N[:, 1]
    cop[:, 4] = -N[:, 0]
    # Torsion: |m_z| ≤ μ ρ f_z with ρ the sole points' mean distance from the centroid, the
    # most friction can resist about z when the load is spread evenly over those points.
    # A line foot resists z moments only by the lateral friction at its two ends, which
    # also carries its lateral force, so it gets half of that.
    xy = (R_FS.T @ (robot.feet[side].points - p_FS[:, None]))[:2]
    rho = float(np.mean(np.linalg.norm(xy, axis=0))) * (0.5 if line_contact else 1.0)
    torsion = np.array([[0.0, 0.0, -mu * rho, 0.0, 0.0, 1.0], [0.0, 0.0, -mu * rho, 0.0, 0.0, -1.0]])
    A_w = limits if robot.is_point_foot else np.vstack([limits, cop, torsion])
    b = np.zeros(len(A_w))
    b[0] = -min_normal_force
    # Point velocities of a rigid foot are Gᵀ [v; ω] (Gᵀ maps a twist to the points as G
    # maps point forces to a wrench): its range is the foot's rows' column space, rank 6
    # of 3k for a plane foot, 5 for a line (no spin about the line moves its points).
    U, sv, _ = np.linalg.svd(G.T, full_matrices=False)
    motion = U[:, sv > 1e-9 * sv[0]]
    offsets = points_F - p_FS[:, None]
    per_shift = np.zeros((0, G.shape[1])) if robot.is_point_foot else np.tile(mu * G[2], (2, 1))
    arrays = (np.asfortranarray(points_F), R_FS, p_FS, G, A_w @ G, b, motion, offsets, per_shift)
    for a in arrays:
        a.setflags(write=False)
    return FootContact(side, robot.foot_frames[side], names, *arrays, rho)


class ContactModel:
    """Holonomic constraints per contact domain and each foot's force limits, for one robot.

    Domains: ``left``/``right`` (single support), ``double``, ``none`` (in the air: internal
    loops only). Rows: contact points of the feet in contact (left first), 3 a point, then the
    robot's internal constraints. For contact rows, h is the current world position of the
    point (held constant while in contact); for internal rows, the loop residual.

    Force limits on one foot's wrench [f; m] in S: f_z ≥ ``min_normal_force``;
    |f_x|, |f_y| ≤ μ (1 − ``friction_margin``) f_z with μ = ``feet.friction``; the CoP
    (−m_y, m_x)/f_z at least ``cop_margin`` (m) inside the sole region; and the yaw moment
    |m_z| ≤ μ ρ f_z (torsional friction, ρ the sole points' mean distance from the centroid,
    halved for line contacts; less with a planned CoP shift, :meth:`friction_constraints`). Point
    feet: the normal force and friction rows only.
    """

    def __init__(self, robot: RobotModel, *, friction_margin: float = 0.0, cop_margin: float = 0.0,
                 min_normal_force: float = 0.0, line_contact: bool = False):
        self.robot = robot
        self.line_contact = not robot.is_point_foot and (robot.is_line_foot or line_contact)
        self.point_contact = robot.is_point_foot
        plant = robot.plant
        self.feet: dict[str, FootContact] = {
            side: _foot_contact(robot, side, self.line_contact, friction_margin, cop_margin, min_normal_force)
            for side in SIDES}
        self._names = {
            domain: tuple(f"{s}_{p}_{a}" for s in sides for p in self.feet[s].point_names for a in "xyz")
            + tuple(f"internal_{i}" for i in range(robot.num_internal_constraints()))
            for domain, sides in DOMAINS.items()
        }
        m = robot.num_internal_constraints()
        self._eye_internal = np.eye(m)
        self._basis_shapes = {domain: (sum(self.feet[s].motion_basis.shape[0] for s in sides) + m,
                                       sum(self.feet[s].motion_basis.shape[1] for s in sides) + m)
                              for domain, sides in DOMAINS.items()}
        if m:
            context = plant.CreateDefaultContext()
            plant.SetPositions(context, robot.nominal.q)
            if np.linalg.matrix_rank(robot.internal_constraints(context).J) < m:
                raise RomocoError(f"{robot.yaml_path}: the internal constraints are not independent")

    def constraints(self, kin: RobotKinematics, domain: str) -> Output:
        """h (as ``y``), J_h and J̇_h·v of ``domain`` at the state of ``kin``.

        A foot's point rows come from its spatial Jacobian at the sole centroid c, which the
        walking outputs read too (one Drake query a foot a tick): for a point P fixed in the
        foot at r = p_P − p_c (world), v_P = v_c + ω × r, so J_P = J_v − [r]× J_ω, and the bias
        a_P = a_c + α × r + ω × (ω × r).
        """
        if domain not in DOMAINS:
            raise ValueError(f"unknown contact domain '{domain}' (one of {', '.join(DOMAINS)})")
        h, J, Jdv = [], [], []
        for side in DOMAINS[domain]:
            foot = self.feet[side]
            R, p = kin.frame_pose(foot.frame)
            J6, bias = kin.spatial_jacobian(foot.frame, foot.p_FS)
            r = R @ foot.offsets_F  # 3×k, points relative to the sole centroid, world
            h.append((r + (R @ foot.p_FS + p)[:, None]).ravel(order="F"))
            Jw, Jv = J6[:3], J6[3:]
            # −[r]× J_ω for all points at once: (k, 3, 3) @ (3, nv).
            J.append((skew(-r.T) @ Jw + Jv).reshape(-1, self.robot.nv))
            W = skew(Jw @ kin.v)
            # a_c + α × r + ω × (ω × r), one row a point.
            Jdv.append((bias[3:] + r.T @ (skew(bias[:3]) + W @ W).T).ravel())
        if self.robot.num_internal_constraints():
            internal = self.robot.internal_constraints(kin.context)
            h.append(internal.h)
            J.append(internal.J)
            Jdv.append(internal.Jdot_v)
        if not J:
            return Output(self._names[domain], np.zeros(0), np.zeros((0, self.robot.nv)), np.zeros(0))
        if len(J) == 1:
            return Output(self._names[domain], h[0], J[0], Jdv[0])
        return Output(self._names[domain], np.concatenate(h), np.concatenate(J), np.concatenate(Jdv))

    def row_space_basis(self, kin: RobotKinematics, domain: str) -> np.ndarray:
        """U (n_h × r) orthonormal, spanning the column space of ``domain``'s J_h (rank r).

        The multi-point contact rows are redundant (rank 6 of 9 for a plane foot); controllers
        impose J_h v̇ = b as Uᵀ J_h v̇ = Uᵀ b, which is the same constraint without redundant
        rows. Built from each foot's constant :attr:`FootContact.motion_basis` turned into world
        (U = blockdiag(R_WS) U_S), not by factorising J_h each tick. The internal loops' rows
        are independent (checked once per robot) and kept as they are.
        """
        rows, cols = self._basis_shapes[domain]
        U = np.zeros((rows, cols))
        i = j = 0
        for side in DOMAINS[domain]:
            U_S = self.feet[side].motion_basis
            k, r = U_S.shape[0] // 3, U_S.shape[1]
            R_WS = self.sole_rotation(kin, side)
            U[i:i + 3 * k, j:j + r] = (R_WS @ U_S.reshape(k, 3, r)).reshape(3 * k, r)
            i, j = i + 3 * k, j + r
        U[i:, j:] = self._eye_internal
        return U

    def sole_rotation(self, kin: RobotKinematics, side: str) -> np.ndarray:
        """R_WS of the foot's sole frame at the state of ``kin`` (a point foot's yaw frame)."""
        if self.point_contact:
            return point_foot_yaw(kin.R_base)
        foot = self.feet[side]
        return kin.frame_pose(foot.frame)[0] @ foot.R_FS

    def sole_center(self, kin: RobotKinematics, side: str) -> np.ndarray:
        """p_WS: the sole centroid in world at the state of ``kin``."""
        foot = self.feet[side]
        R, p = kin.frame_pose(foot.frame)
        return R @ foot.p_FS + p

    def friction_constraints(self, kin: RobotKinematics, side: str, cop_shift: float = 0.0
                             ) -> tuple[np.ndarray, np.ndarray]:
        """A, b with A f ≤ b on the foot's stacked point forces f expressed in world. With the CoP
        planned ``cop_shift`` (m) off the sole centroid, the torsion limit is μ (ρ − |shift|) f_z:
        the load no longer spread evenly, friction resists less yaw moment, as the rectangle's
        contact wrench cone lowers its yaw bound by μ |τ_y| (:mod:`~romoco_drake.rom.wrench_cone`).
        Found on G1 stepping down stairs with its CoP toward the heel: under the even-load limit its
        stance foot spun 10-15° about the heel as the swing leg reached forward."""
        foot = self.feet[side]
        R_WS = self.sole_rotation(kin, side)
        A_S = foot.A_S
        if cop_shift != 0.0 and len(foot.torsion_per_shift):
            A_S = A_S.copy()
            A_S[-2:] += min(abs(cop_shift), foot.torsion_radius) * foot.torsion_per_shift
        rows, cols = A_S.shape
        # Per point: A_S,i f_S,i = A_S,i R_SW f_W,i.
        A = (A_S.reshape(rows, cols // 3, 3) @ R_WS.T).reshape(rows, cols)
        return A, foot.b
