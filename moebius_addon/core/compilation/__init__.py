"""Compiling the numerical kernels: numba's threading layer, the kernels shipped with the zip,
the notice shown while numba compiles, and the warm-up that compiles a first session's paths.
"""
