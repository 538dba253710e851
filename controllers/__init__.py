"""GRU model, δISS certificates, observer, constraint tightening and robust MPC.

This package knows nothing of FMUs: it works on arrays in normalised units. Only
:mod:`controllers.training` needs torch; everything else runs on numpy and casadi.
"""
