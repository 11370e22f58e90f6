"""Reduced-order models of walking (numpy only, no pydrake).

All models share one step-to-step (S2S) framework: a linear pendulum flow per contact domain
plus an impact map at the support switch, giving ``x_{k+1} = A x_k + B u_k`` on the state at the
end of single support. Each plane (sagittal, lateral) uses ``x = (p, L)``: the horizontal CoM
position relative to the stance pivot and the mass-normalised angular momentum about the pivot.
"""
