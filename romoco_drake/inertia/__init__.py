"""Centroidal inertia network (CCINN) and whole-body orientation (WBO) of the VI-MPC paper.

``ccinn`` and ``wbo`` are numpy-only inference the control loop may import; ``system`` wraps
the horizon prediction as a LeafSystem. ``data`` (IK sampling) and ``train`` (scikit-learn)
build the shipped files and are never imported by the control loop.
"""
