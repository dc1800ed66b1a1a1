"""The shared numerical core: numba kernels on plain float arrays (DESIGN.md, "Estimation core")."""
