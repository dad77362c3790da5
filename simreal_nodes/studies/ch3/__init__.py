"""Thesis chapter 3: local PGD (ℓ-PGD) on sub-domains of the parameter / time axes and its §3.3 benchmark problems.

``local_pgd``: the solver and the Cℓ / MNOℓ / kℓ partitionings, over its own Kronecker-sum operator and separated
solution (independent of :mod:`simreal_nodes.rom.separated`, the runtime model format); ``problems``: the
full-order models (cantilever, heat, parametric heat). Used by tests/studies and benchmarks/local_pgd.py.
"""
