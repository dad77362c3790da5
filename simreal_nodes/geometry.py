"""Rigid transforms: 4x4 homogeneous matrices, quaternions (x, y, z, w as in ROS), SO(3) maps.

Naming: ``T_a_b`` maps coordinates in frame b to frame a (x_a = T_a_b @ x_b), so ``T_map_cam`` is
the camera pose in the map, the transform that TF publishes as parent ``map``, child ``camera``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray


def quat_to_matrix(q: NDArray[np.float64] | Sequence[float]) -> NDArray[np.float64]:
    """(x, y, z, w) -> 3x3 rotation; normalizes; a zero quaternion is an error."""
    x, y, z, w = (float(v) for v in q)
    n = x * x + y * y + z * z + w * w
    if not np.isfinite(n) or n < 1e-12:
        raise ValueError(f"quaternion {list(q)} has no rotation (zero or non-finite norm)")
    s = 2.0 / n
    return np.array([
        [1 - s * (y * y + z * z), s * (x * y - z * w), s * (x * z + y * w)],
        [s * (x * y + z * w), 1 - s * (x * x + z * z), s * (y * z - x * w)],
        [s * (x * z - y * w), s * (y * z + x * w), 1 - s * (x * x + y * y)],
    ])


def matrix_to_quat(R: ArrayLike) -> NDArray[np.float64]:
    """3x3 rotation -> (x, y, z, w) with w >= 0 (Shepperd's method)."""
    R = np.asarray(R, dtype=np.float64)
    t = np.trace(R)
    if t > 0:
        s = 2.0 * np.sqrt(t + 1.0)
        q = np.array([(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, 0.25 * s])
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = 2.0 * np.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q = np.array([0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s, (R[2, 1] - R[1, 2]) / s])
    elif R[1, 1] > R[2, 2]:
        s = 2.0 * np.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2])
        q = np.array([(R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s, (R[0, 2] - R[2, 0]) / s])
    else:
        s = 2.0 * np.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1])
        q = np.array([(R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s, (R[1, 0] - R[0, 1]) / s])
    q /= np.linalg.norm(q)
    return q if q[3] >= 0 else -q


def pose7_to_matrix(p: NDArray[np.float64] | Sequence[float]) -> NDArray[np.float64]:
    """[x, y, z, qx, qy, qz, qw] -> 4x4."""
    T = np.eye(4)
    T[:3, :3] = quat_to_matrix(p[3:7])
    T[:3, 3] = p[:3]
    return T


def matrix_to_pose7(T: ArrayLike) -> NDArray[np.float64]:
    T = np.asarray(T)
    return np.concatenate([T[:3, 3], matrix_to_quat(T[:3, :3])])


def make_T(R: ArrayLike | None = None, t: ArrayLike | None = None) -> NDArray[np.float64]:
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    if t is not None:
        T[:3, 3] = np.asarray(t).ravel()
    return T


def inv(T: ArrayLike) -> NDArray[np.float64]:
    """Inverse of a rigid 4x4 transform."""
    T = np.asarray(T)
    Ti = np.eye(4)
    Ti[:3, :3] = T[:3, :3].T
    Ti[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return Ti


def transform(T: NDArray[np.float64], P: ArrayLike) -> NDArray[np.float64]:
    """Apply a 4x4 transform to (N, 3) points."""
    P = np.asarray(P, dtype=np.float64)
    return P @ T[:3, :3].T + T[:3, 3]


def hat(w: NDArray[np.float64] | Sequence[float]) -> NDArray[np.float64]:
    """so(3) hat: w -> [w]x."""
    return np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]], dtype=np.float64)


def exp_so3(w: ArrayLike) -> NDArray[np.float64]:
    """Rodrigues: rotation vector -> rotation matrix."""
    w = np.asarray(w, dtype=np.float64)
    th = np.linalg.norm(w)
    K = hat(w)
    if th < 1e-10:
        return np.eye(3) + K + 0.5 * K @ K
    R: NDArray[np.float64] = np.eye(3) + np.sin(th) / th * K + (1 - np.cos(th)) / th**2 * K @ K
    return R


def log_so3(R: ArrayLike) -> NDArray[np.float64]:
    """Rotation matrix -> rotation vector (angle in [0, pi])."""
    R = np.asarray(R, dtype=np.float64)
    c = np.clip((np.trace(R) - 1) / 2, -1.0, 1.0)
    th = np.arccos(c)
    if th < 1e-8:
        return np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / 2
    if np.pi - th < 1e-6:
        # near pi: axis from the symmetric part
        A = (R + np.eye(3)) / 2
        k = int(np.argmax(np.diag(A)))
        axis = A[:, k] / np.sqrt(max(A[k, k], 1e-15))
        w_pi: NDArray[np.float64] = axis / np.linalg.norm(axis) * th
        return w_pi
    w: NDArray[np.float64] = th / (2 * np.sin(th)) * np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    return w


def rot_axis(axis: str, angle: float) -> NDArray[np.float64]:
    """Rotation about a principal axis 'x', 'y' or 'z' by ``angle`` radians."""
    c, s = np.cos(angle), np.sin(angle)
    if axis == "x":
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    if axis == "y":
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    if axis == "z":
        return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    raise ValueError(f"axis must be 'x', 'y' or 'z', not {axis!r}")


def turn_about_z(R: ArrayLike) -> float:
    """The turn (radians) about z of a rotation (or the rotation block of a transform) whose z axis is (nearly)
    that of its frame: exact for a pure turn about z, the best fitting turn when the axis is tilted a little."""
    M = np.asarray(R, dtype=np.float64)
    return float(np.arctan2(M[1, 0] - M[0, 1], M[0, 0] + M[1, 1]))


def look_at(eye: ArrayLike, target: ArrayLike, up: ArrayLike = (0, 0, 1)) -> NDArray[np.float64]:
    """Camera pose T_world_cam (optical frame: z forward, x right, y down) looking at target."""
    eye, target, up = (np.asarray(v, dtype=np.float64) for v in (eye, target, up))
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-9:
        x = np.cross(z, [0, 1, 0] if abs(z[1]) < 0.9 else [1, 0, 0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return make_T(np.stack([x, y, z], axis=1), eye)


def vertex_normals(V: ArrayLike, F: ArrayLike) -> NDArray[np.float64]:
    """Unit vertex normals of a triangle mesh: the area-weighted sum of the incident faces' normals
    (zero for a vertex on no face)."""
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    fn = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    idx = F.ravel()
    n = np.stack([np.bincount(idx, weights=np.repeat(fn[:, c], 3), minlength=len(V)) for c in range(3)], axis=1)
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    return n / np.where(ln > 0, ln, 1.0)


def outward_triangles(V: ArrayLike, F: ArrayLike) -> NDArray[np.int64] | None:
    """The triangles of a closed, consistently wound surface, wound counter-clockwise seen from outside
    (flipped if they were the other way); None if the surface is open or its winding is inconsistent
    (every directed edge must appear once and its reverse once). Back faces of such a surface are never
    visible from outside it, so a renderer may cull them."""
    F = np.asarray(F, dtype=np.int64)
    if F.ndim != 2 or F.shape[1] != 3 or not len(F):
        return None
    e = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    n = int(F.max()) + 1
    key = e[:, 0] * n + e[:, 1]
    rkey = e[:, 1] * n + e[:, 0]
    if len(np.unique(key)) != len(key) or not np.all(np.isin(rkey, key)):
        return None
    V = np.asarray(V, dtype=np.float64)
    vol = np.einsum("ij,ij->", V[F[:, 0]], np.cross(V[F[:, 1]], V[F[:, 2]])) / 6.0
    if vol == 0 or not np.isfinite(vol):
        return None
    return F if vol > 0 else F[:, ::-1].copy()
