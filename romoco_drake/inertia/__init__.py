"""Centroidal inertia network (CCINN) and whole-body orientation (WBO) of the VI-MPC paper.

``ccinn`` and ``wbo`` are numpy inference the control loop may import (they find their model
files through ``robots.source``, as every model file is found); ``system`` wraps the horizon
prediction as a LeafSystem. ``collision``, ``data`` (IK sampling), ``wbo_fit`` and ``train``
(scikit-learn) build the shipped files and are never imported by the control loop. In the
layering the package sits beside ``embedding``: it imports ``robots`` (IK, the plant's
centroidal quantities) and ``planners`` may import its inference.
"""
