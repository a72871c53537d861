"""The HASEL wheel's observer, MPC and identification (the numerical cores import no rclpy).

Importing the package pins OpenBLAS's kernels first (:mod:`.numerics`), so that the
identification makes the same choices on every Linux x86-64 machine with AVX2.
"""
from .numerics import pin_blas_kernels

pin_blas_kernels()
