"""Numerical building blocks shared by the models, paths and controllers."""
