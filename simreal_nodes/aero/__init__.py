"""Car aerodynamics in augmented reality (thesis ch. 6), ROS-free.

Offline: ``cars`` (the procedural car family), ``grid`` (the 140 x 40 x 20 grid and Eq. 6.1's presence function),
``openfoam`` (one car's flow with OpenFOAM), ``database`` (the sweep over Dask and the versioned HDF5 database).
Online: ``manifold`` (LLE of the shapes, incremental embedding, Eq. 6.4), ``capture`` (Alg. 6.1: a SLAM map to a
presence vector), ``streamlines`` (the flow as drawable tubes). Nothing online runs CFD.
"""
