"""Trajectory evaluation: Umeyama alignment, absolute trajectory error (ATE) and relative pose error (RPE),
TUM-format files and PoseStamped topics of bags (`simreal eval-trajectory`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from simreal_nodes import geometry as G
from simreal_nodes.errors import SimrealError


def umeyama(src: np.ndarray, dst: np.ndarray, with_scale: bool = False) -> tuple[np.ndarray, np.ndarray, float]:
    """R, t, s minimizing sum ||dst - (s R src + t)||^2 (Umeyama 1991)."""
    src, dst = np.asarray(src, np.float64), np.asarray(dst, np.float64)
    if len(src) < 3:
        raise SimrealError(f"alignment needs at least 3 poses, got {len(src)}")
    mu_s, mu_d = src.mean(0), dst.mean(0)
    a, b = src - mu_s, dst - mu_d
    C = b.T @ a / len(src)
    U, S, Vt = np.linalg.svd(C)
    D = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        D[2, 2] = -1
    R = U @ D @ Vt
    var = np.mean(np.sum(a * a, axis=1))
    s = float(np.trace(np.diag(S) @ D) / var) if with_scale and var > 0 else 1.0
    t = mu_d - s * R @ mu_s
    return R, t, s


def ate(est: np.ndarray, ref: np.ndarray, with_scale: bool = False) -> dict:
    """ATE of positions after Umeyama alignment (with scale for monocular trajectories)."""
    R, t, s = umeyama(est, ref, with_scale)
    aligned = s * est @ R.T + t
    e = np.linalg.norm(aligned - ref, axis=1)
    length = float(np.sum(np.linalg.norm(np.diff(ref, axis=0), axis=1)))
    return {"rmse": float(np.sqrt(np.mean(e ** 2))), "mean": float(e.mean()), "median": float(np.median(e)),
            "max": float(e.max()), "n": len(e), "scale": s, "length": length,
            "rmse_pct_length": 100.0 * float(np.sqrt(np.mean(e ** 2))) / length if length > 0 else float("nan"),
            "R": R, "t": t, "errors": e}


def rpe(est_T: list[np.ndarray | None], ref_T: list[np.ndarray], delta: int = 1, scale: float = 1.0) -> dict:
    """Relative pose error over ``delta`` frames: translation (m) and rotation (deg) RMSE. A frame without an
    estimate (None: lost) leaves out the pairs it belongs to."""
    et_list: list[np.floating] = []
    er_list: list[np.floating] = []
    for i in range(len(est_T) - delta):
        a, b = est_T[i], est_T[i + delta]
        if a is None or b is None:
            continue
        dE = G.inv(a) @ b
        dR = G.inv(ref_T[i]) @ ref_T[i + delta]
        dE = dE.copy()
        dE[:3, 3] *= scale
        err = G.inv(dR) @ dE
        et_list.append(np.linalg.norm(err[:3, 3]))
        er_list.append(np.rad2deg(np.linalg.norm(G.log_so3(err[:3, :3]))))
    et, er = np.asarray(et_list), np.asarray(er_list)
    return {"trans_rmse": float(np.sqrt(np.mean(et ** 2))) if len(et) else float("nan"),
            "rot_rmse_deg": float(np.sqrt(np.mean(er ** 2))) if len(er) else float("nan"), "n": len(et), "delta": delta}


def read_tum(path: str | Path) -> tuple[np.ndarray, list[np.ndarray]]:
    """TUM format: 'timestamp tx ty tz qx qy qz qw' per line, '#' comments."""
    path = Path(path)
    if not path.exists():
        raise SimrealError(f"trajectory file not found: {path}")
    ts, Ts = [], []
    for n, line in enumerate(path.read_text().splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        v = line.replace(",", " ").split()
        if len(v) != 8:
            raise SimrealError(f"{path}:{n}: expected 8 numbers (t tx ty tz qx qy qz qw), found {len(v)}")
        try:
            x = [float(a) for a in v]
        except ValueError:
            raise SimrealError(f"{path}:{n}: not numbers: {line!r}") from None
        ts.append(x[0])
        Ts.append(G.pose7_to_matrix(x[1:]))
    return np.asarray(ts), Ts


def write_tum(path: str | Path, stamps, Ts) -> None:
    lines = ["# timestamp tx ty tz qx qy qz qw"]
    for t, T in zip(stamps, Ts):
        p = G.matrix_to_pose7(T)
        lines.append(f"{t:.9f} " + " ".join(f"{x:.9f}" for x in p))
    Path(path).write_text("\n".join(lines) + "\n")


def read_bag_poses(path: str | Path, topic: str) -> tuple[np.ndarray, list[np.ndarray]]:
    """Header stamps (s) and poses of a PoseStamped topic in a bag."""
    from simreal_nodes.io import bags

    ts, Ts = [], []
    for m in bags.read_bag(path, topics=[topic]):
        o = bags.decode(m)
        p = o.pose
        ts.append(bags.stamp_ns(o) * 1e-9)
        Ts.append(G.pose7_to_matrix([p.position.x, p.position.y, p.position.z, p.orientation.x, p.orientation.y,
                                     p.orientation.z, p.orientation.w]))
    if not Ts:
        raise SimrealError(f"bag {path} has no poses on {topic}")
    return np.asarray(ts), Ts


def associate(t_est, t_ref, max_dt: float = 0.02) -> tuple[np.ndarray, np.ndarray]:
    """Indices pairing each estimate with the reference of the nearest stamp (within max_dt seconds)."""
    t_ref = np.asarray(t_ref)
    order = np.argsort(t_ref)
    tr = t_ref[order]
    ie, ir = [], []
    for i, t in enumerate(t_est):
        k = np.searchsorted(tr, t)
        best = None
        for j in (k - 1, k):
            if 0 <= j < len(tr) and (best is None or abs(tr[j] - t) < abs(tr[best] - t)):
                best = j
        if best is not None and abs(tr[best] - t) <= max_dt:
            ie.append(i)
            ir.append(order[best])
    return np.asarray(ie, np.int64), np.asarray(ir, np.int64)
