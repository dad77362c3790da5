"""The boot measurement benchmark's truth: where the independent solve puts the material point a link claims."""

import numpy as np

from benchmarks.boot_measurements import truth_pixels
from simreal_nodes import geometry as G
from simreal_nodes.synth.truth import LeverTruth


def test_truth_pixels_snap_to_the_truth_surface_and_move_with_its_displacement():
    # one triangle 1 m in front of the camera (z = 1), displaced 10 mm along x at theta = 1, half that at 0.5
    P = np.array([[-0.1, -0.1, 1.0], [0.1, -0.1, 1.0], [0.0, 0.1, 1.0]])
    U = np.zeros((2, 3, 3))
    U[1, :, 0] = 0.01
    truth = LeverTruth(P, np.array([[0, 1, 2]]), np.array([0.0, 1.0]), U)
    K = np.array([[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]])
    X = np.array([[0.0, 0.0, 1.004], [0.02, -0.05, 0.995]])  # 4 and 5 mm off the surface: snapped onto it
    at_rest = truth_pixels(truth, np.eye(4), np.eye(4), K, X, 0.0)
    np.testing.assert_allclose(at_rest, [[320.0, 240.0], [330.0, 215.0]], atol=1e-3)
    half = truth_pixels(truth, np.eye(4), np.eye(4), K, X, 0.5)
    np.testing.assert_allclose(half - at_rest, [[2.5, 0.0], [2.5, 0.0]], atol=1e-3)
    # the truth placed elsewhere in the map, the camera too: the same pixels for the same material points
    T = G.make_T(G.rot_axis("z", 0.7), np.array([0.3, -0.2, 0.5]))
    moved = truth_pixels(truth, T, T, K, G.transform(T, X), 0.5)
    np.testing.assert_allclose(moved, half, atol=1e-3)
