"""Local PGD (thesis ch. 3) on the chapter's three problems: our Fig. 3.5c-d, 3.9, 3.10, 3.11, 3.12, 3.13 and
the time / memory comparison of §3.5, with global PGD, global POD and HOSVD as baselines.

    ./run bench local_pgd
    # writes benchmarks/results/local_pgd.{json,md,png} and docs/local_pgd.md (+ figures)

Errors are relative L2 (Frobenius over the grid) against the full-order model with the same discretisation;
every PGD stops on its own a-priori indicator (the full-order solution is only used to score it).
"""

from __future__ import annotations

import json
import time
import warnings
from pathlib import Path

import numpy as np

from benchmarks.common import RESULTS, machine, markdown_table
from simreal_nodes.rom.nipgd import hosvd
from simreal_nodes.studies.ch3 import local_pgd as LP
from simreal_nodes.studies.ch3.problems import cantilever, euler_bernoulli_tip, heat, heat_series

DOCS = Path(__file__).resolve().parent.parent / "docs"
FIG = DOCS / "figures"
THESIS_GLOBAL_PGD_1E4 = {"2pi/7": 211, "5pi/7": 382}


def _timed(f, *a, **k):
    t0 = time.perf_counter()
    out = f(*a, **k)
    return out, time.perf_counter() - t0


def _online_ms(full, reps=3) -> float:
    t0 = time.perf_counter()
    for _ in range(reps):
        full()
    return 1e3 * (time.perf_counter() - t0) / reps


# ------------------------------------------------------------------------------------------------
def bench_cantilever() -> dict:
    c = cantilever()
    U = c.solve_fom()
    fr = c.free
    pr = LP.ParametricStatic(c.K[fr][:, fr], c.T[fr].toarray())
    Uf = U[fr]
    iy = np.isin(fr, c.uy_dofs)
    tip = int(np.where(fr == c.tip_dof)[0][0])
    eb = euler_bernoulli_tip(c)
    n_s = pr.axes[0]

    def scores(Ul):
        return {"l2": LP.rel_error(Ul[iy], Uf[iy]), "tip_vs_eb": abs(Ul[tip, -1] - eb) / abs(eb),
                "per_s": (np.linalg.norm(Ul[iy] - Uf[iy], axis=0) / np.linalg.norm(Uf[iy], axis=0)).tolist()}

    out = {"fem_tip_vs_eb": abs(U[c.tip_dof, -1] - eb) / abs(eb), "eb_tip": eb, "fem_tip": float(U[c.tip_dof, -1]),
           "n_dof": int(U.shape[0]), "n_s": n_s}
    ops, B = pr.block((slice(0, n_s),), None)
    g, tg = _timed(LP.pgd, ops, B, tol=1e-12, max_modes=12)
    Us, sv, Vt = np.linalg.svd(Uf, full_matrices=False)
    out["global_pgd"] = [dict(modes=n, **scores(g.full(n))) for n in range(1, 13)]
    out["global_pod"] = [dict(modes=n, **scores((Us[:, :n] * sv[:n]) @ Vt[:n])) for n in range(1, 13)]
    out["global_pgd_time_s"] = tg
    out["global_pgd_storage_6"] = 6 * (Uf.shape[0] + n_s)
    loc = {}
    for M in (1, 2, 3, 4):
        cuts = [LP.constant_partition(n_s, 9)]
        L = LP.solve_local(pr, cuts, tol=1e-12, max_modes=M)
        loc.setdefault("C", []).append(dict(modes=M, divisions=9, total=L.total_modes, storage=L.storage,
                                            offline_s=L.offline_s, **scores(L.full())))
        (cm, Lm), t = _timed(LP.mno_partition, pr, M, tol=1e-2)
        loc.setdefault("MNO", []).append(dict(modes=M, divisions=len(cm[0]) - 1, total=Lm.total_modes,
                                              storage=Lm.storage, offline_s=t, cuts=cm[0].tolist(),
                                              **scores(Lm.full())))
        (ck, km), t1 = _timed(LP.kpca_partition, pr, 9, block=11, eps=0.15, seed=0)
        Lk = LP.solve_local(pr, ck, tol=1e-12, max_modes=M)
        loc.setdefault("k", []).append(dict(modes=M, divisions=len(ck[0]) - 1, total=Lk.total_modes,
                                            storage=Lk.storage, offline_s=t1 + Lk.offline_s, cuts=ck[0].tolist(),
                                            **scores(Lk.full())))
    out["local"] = loc
    out["kpca_h"] = km.h_origin.tolist()
    out["kpca_cuts"] = ck[0].tolist()
    out["s"] = c.s.tolist()
    # what global PGD needs to match Cℓ-PGD with 2 modes in 9 divisions
    c2 = next(r for r in loc["C"] if r["modes"] == 2)
    out["global_modes_matching_C9x2"] = next((r["modes"] for r in out["global_pgd"] if r["l2"] <= c2["l2"]), None)
    out["global_modes_matching_C9x2_tip"] = next(
        (r["modes"] for r in out["global_pgd"] if r["tip_vs_eb"] <= c2["tip_vs_eb"] * 1.0001), None)
    out["online_ms"] = {"global_pgd_6": _online_ms(lambda: g.full(6))}
    L2 = LP.solve_local(pr, [LP.constant_partition(n_s, 9)], tol=1e-12, max_modes=2)
    out["online_ms"]["C9x2"] = _online_ms(L2.full)
    return out


# ------------------------------------------------------------------------------------------------
def _sweep_local(pr, Uref, strategies, tols, update):
    rows = []
    for name, make in strategies:
        for tol in tols:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", LP.PartitionWarning)
                t0 = time.perf_counter()
                L, extra = make(tol, update)
                off = time.perf_counter() - t0
            m = L.modes.ravel()
            rows.append(dict(method=name, tol=tol, update=update, error=LP.rel_error(L.full(), Uref),
                             max_local=int(m.max()), total=int(m.sum()), subdomains=int(m.size),
                             nonzero_subdomains=int((m > 0).sum()), storage=L.storage, offline_s=off,
                             online_ms=_online_ms(L.full, 2), modes_per_subdomain=m.tolist(),
                             cuts=[c.tolist() for c in L.cuts], **extra))
    return rows


def bench_heat(xf_name: str, xf: float, Nx=301, Nt=401) -> dict:
    h = heat(Nx, Nt, x_f=xf)
    Ufom, t_fom = _timed(h.solve_fom)
    series = heat_series(h.p, h.x, h.t)
    out = {"x_f": xf_name, "Nx": Nx, "Nt": Nt, "fom_s": t_fom, "fom_vs_series": LP.rel_error(Ufom, series)}
    h2 = heat(2 * Nx - 1, 2 * Nt - 1, x_f=xf)
    out["fom_vs_series_refined"] = LP.rel_error(h2.solve_fom(), heat_series(h2.p, h2.x, h2.t))
    Uref = Ufom[1:-1, 1:]
    pr = LP.TransientHeat(h.M, h.K, h.B, h.dt, [h.p.k])
    ops, B = pr.block((slice(0, Nt - 1),), None)
    glob = {}
    for upd, cap in ((False, 450), (True, 200)):
        g, t = _timed(LP.pgd, ops, B, tol=1e-8, max_modes=cap, update=upd)
        ns = np.unique(np.r_[np.arange(1, 20), np.arange(20, g.n_modes + 1, 5), g.n_modes])
        err = LP.error_curve(g.full, Uref, ns)
        key = "global_pgd_update" if upd else "global_pgd"
        glob[key] = dict(modes=ns.tolist(), error=err.tolist(), time_s=t, online_ms=_online_ms(g.full, 2),
                         storage_per_mode=Nx - 2 + Nt - 1,
                         modes_1e4=int(ns[np.argmax(err < 1e-4)]) if np.any(err < 1e-4) else None)
    Us, sv, Vt = np.linalg.svd(Uref, full_matrices=False)
    ns = np.arange(1, 201)
    err = np.array([LP.rel_error((Us[:, :n] * sv[:n]) @ Vt[:n], Uref) for n in ns])
    glob["global_pod"] = dict(modes=ns.tolist(), error=err.tolist(),
                              modes_1e4=int(ns[np.argmax(err < 1e-4)]) if np.any(err < 1e-4) else None)
    out["global"] = glob

    nt = Nt - 1
    cuts_k, km = LP.kpca_partition(pr, 10, block=10, eps=0.12, seed=0)

    def C(tol, upd):
        return LP.solve_local(pr, [LP.constant_partition(nt, 10)], tol=tol, update=upd), {}

    def MNO(tol, upd):
        _cuts, L = LP.mno_partition(pr, 20 if upd else 30, tol=tol, update=upd)
        return L, {}

    def K(tol, upd):
        return LP.solve_local(pr, cuts_k, tol=tol, update=upd), {}

    strategies = [("Cℓ-PGD", C), ("MNOℓ-PGD", MNO), ("kℓ-PGD", K)]
    out["local"] = (_sweep_local(pr, Uref, strategies, [1e-2, 1e-3, 1e-4], False)
                    + _sweep_local(pr, Uref, strategies, [1e-2, 1e-3, 1e-4, 1e-5], True))
    out["kpca"] = dict(t=h.t[1:].tolist(), h=km.h_origin.tolist(), cuts=[c.tolist() for c in km.cuts], sigma=km.sigma,
                       eigenvalues=km.eigenvalues.tolist(), notes=km.notes)
    # the knob of kℓ-PGD: the Hausdorff threshold ε (fraction of the k-PCA cloud's diameter)
    sweep = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LP.PartitionWarning)
        for eps in (0.08, 0.12, 0.2, 0.3, 0.45):
            (cuts, _), tp = _timed(LP.kpca_partition, pr, 10, block=10, eps=eps, seed=0)
            L, ts = _timed(LP.solve_local, pr, cuts, tol=1e-4)
            m = L.modes.ravel()
            sweep.append(dict(eps=eps, subdomains=int(m.size), max_local=int(m.max()), total=int(m.sum()),
                              error=LP.rel_error(L.full(), Uref), storage=L.storage, offline_s=tp + ts))
    out["kpca_eps_sweep"] = sweep
    return out


def bench_parametric(Nx=151, Nt=201, Nk=26) -> dict:
    kg = np.linspace(0.0, 0.25, Nk)
    h = heat(Nx, Nt, x_f=5 * np.pi / 7, k_grid=kg)
    Ufom, t_fom = _timed(h.solve_fom_parametric)
    Uref = Ufom[1:-1, 1:, :]
    j05 = int(np.argmin(np.abs(kg - 0.05)))
    pr = LP.TransientHeat(h.M, h.K, h.B, h.dt, kg)
    out = {"Nx": Nx, "Nt": Nt, "Nk": Nk, "k": kg.tolist(), "fom_s": t_fom}

    def err05(U):
        return LP.rel_error(U[:, :, j05], Uref[:, :, j05])

    ops, B = pr.block((slice(0, Nt - 1), slice(0, Nk)), None)
    for key, residual in (("global_pgd_galerkin", "galerkin"), ("global_pgd", "minimal")):
        g, t = _timed(LP.pgd, ops, B, tol=1e-8, max_modes=250, residual=residual)
        ns = np.unique(np.r_[np.arange(1, 20), np.arange(20, g.n_modes + 1, 10), g.n_modes])
        e = [err05(g.full(int(n))) for n in ns]
        out[key] = dict(modes=ns.tolist(), error=e, error_all=LP.rel_error(g.full(), Uref), time_s=t,
                        storage=g.storage, online_ms=_online_ms(g.full, 2), residual=residual)
    hs = []
    for r in (1, 2, 4, 8, 12, 16, 20, 26, 30, 40, 50, 60):
        tk, tt = _timed(hosvd, Uref, [r, r, min(r, Nk)])
        hs.append(dict(rank=r, error=err05(tk.full()), storage=tk.storage, time_s=tt))
    out["hosvd"] = hs
    nt = Nt - 1
    rows = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LP.PartitionWarning)
        (ck, km), tk = _timed(LP.kpca_partition, pr, [8, 2], block=10, eps=0.15, seed=0, max_parts=20)
        for name, cuts in (("Cℓ-PGD", [LP.constant_partition(nt, 8), LP.constant_partition(Nk, 2)]), ("kℓ-PGD", ck)):
            for tol in (1e-2, 1e-3, 1e-4):
                L = LP.solve_local(pr, cuts, tol=tol, max_modes=250)
                m = L.modes.ravel()
                rows.append(dict(method=name, tol=tol, error=err05(L.full()), error_all=LP.rel_error(L.full(), Uref),
                                 max_local=int(m.max()), total=int(m.sum()), subdomains=int(m.size), storage=L.storage,
                                 offline_s=L.offline_s + (tk if name == "kℓ-PGD" else 0.0),
                                 online_ms=_online_ms(L.full, 2), cuts=[c.tolist() for c in cuts]))
    out["local"] = rows
    out["kpca"] = dict(h=km.h_origin.tolist(), cuts=[c.tolist() for c in km.cuts], sigma=km.sigma, notes=km.notes)
    return out


# ------------------------------------------------------------------------------------------------
def figures(res: dict) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    FIG.mkdir(parents=True, exist_ok=True)
    names = []
    cols = {"Cℓ-PGD": "tab:green", "MNOℓ-PGD": "tab:red", "kℓ-PGD": "tab:purple"}

    # Fig. 3.5c-d
    ca = res["cantilever"]
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    m = [r["modes"] for r in ca["global_pgd"]]
    ax[0].semilogy(m, [r["tip_vs_eb"] for r in ca["global_pgd"]], "o-", label="global PGD")
    ax[0].semilogy(m, [r["tip_vs_eb"] for r in ca["global_pod"]], "x--", label="global POD")
    for key, lab in (("C", "Cℓ-PGD (9 div.)"), ("MNO", "MNOℓ-PGD"), ("k", "kℓ-PGD")):
        rr = ca["local"][key]
        ax[0].semilogy([r["modes"] for r in rr], [r["tip_vs_eb"] for r in rr], "s-",
                       label=lab + " (modes / sub-domain)")
    ax[0].axhline(ca["fem_tip_vs_eb"], color="k", lw=1, label="FEM")
    ax[0].set_xlabel("modes (load modes per sub-domain for ℓ-PGD)")
    ax[0].set_ylabel("relative tip error vs Euler–Bernoulli (s = 9 m)")
    ax[0].set_title("Fig. 3.5c (ours)")
    ax[0].legend(fontsize=7)
    s = ca["s"]
    for lab, r in (("global PGD, 2 modes", ca["global_pgd"][1]), ("global PGD, 6 modes", ca["global_pgd"][5]),
                   ("global POD, 6 modes", ca["global_pod"][5]), ("Cℓ-PGD 9 × 2", ca["local"]["C"][1]),
                   ("MNOℓ-PGD M = 2", ca["local"]["MNO"][1]), ("kℓ-PGD × 2", ca["local"]["k"][1])):
        ax[1].semilogy(s, np.maximum(r["per_s"], 1e-16), label=lab)
    ax[1].set_xlabel("load position s (m)")
    ax[1].set_ylabel("relative L2 error of u_y vs FEM")
    ax[1].set_title("Fig. 3.5d (ours)")
    ax[1].legend(fontsize=7)
    fig.savefig(FIG / "fig3_5cd.png", dpi=100, bbox_inches="tight")
    plt.close(fig)
    names.append("fig3_5cd.png")

    # Fig. 3.9 / 3.10 / 3.11 for both x_f
    for key in ("heat_2pi7", "heat_5pi7"):
        hr = res[key]
        fig, ax = plt.subplots(1, 3, figsize=(16, 4))
        for gk, st in (("global_pgd", "-"), ("global_pgd_update", "--"), ("global_pod", ":")):
            gg = hr["global"][gk]
            ax[0].semilogy(gg["modes"], gg["error"], st, label=gk.replace("_", " "))
        for upd, mk in ((False, "o"), (True, "s")):
            for meth, col in cols.items():
                rr = [r for r in hr["local"] if r["method"] == meth and r["update"] == upd]
                ax[0].semilogy([r["max_local"] for r in rr], [r["error"] for r in rr], mk + "-", color=col,
                               label=f"{meth} (max modes / sub-domain){' + update' if upd else ''}")
        ax[0].axhline(1e-4, color="k", lw=0.8)
        ax[0].set_xlabel("modes")
        ax[0].set_ylabel("relative L2 error vs FEM")
        ax[0].set_title(f"Fig. 3.9 (ours), x_f = {hr['x_f']}")
        ax[0].legend(fontsize=6)
        for i, (meth, col) in enumerate(cols.items()):
            rr = [r for r in hr["local"] if r["method"] == meth and r["update"] and r["tol"] == 1e-4]
            if rr:
                r = rr[0]
                ax[1].bar(np.arange(len(r["modes_per_subdomain"])) + 0.27 * (i - 1), r["modes_per_subdomain"], 0.27,
                          color=col, label=f"{meth}: {r['subdomains']} sub-domains, total {r['total']}")
        ax[1].set_xlabel("sub-domain (time order)")
        ax[1].set_ylabel("local modes (tol 1e-4, with update)")
        ax[1].set_title("Fig. 3.10 (ours)")
        ax[1].legend(fontsize=7)
        kp = hr["kpca"]
        ax[2].plot(kp["t"], kp["h"], "r-")
        for c in kp["cuts"][0][1:-1]:
            ax[2].axvline(kp["t"][c], color="b", lw=0.6)
        ax[2].set_xlabel("t (s)")
        ax[2].set_ylabel("Hausdorff distance of k-PCA curve to origin")
        ax[2].set_title("Fig. 3.11 (ours)")
        fig.savefig(FIG / f"fig3_9_10_11_{key}.png", dpi=100, bbox_inches="tight")
        plt.close(fig)
        names.append(f"fig3_9_10_11_{key}.png")

    # Fig. 3.12 / 3.13
    pa = res["parametric"]
    fig = plt.figure(figsize=(12, 4))
    ax = fig.add_subplot(1, 2, 1)
    ax.semilogy(pa["global_pgd"]["modes"], pa["global_pgd"]["error"], "-", label="global PGD (minimal residual)")
    ax.semilogy(pa["global_pgd_galerkin"]["modes"], pa["global_pgd_galerkin"]["error"], ":", color="gray",
                label="global PGD (Galerkin)")
    ax.semilogy([r["rank"] for r in pa["hosvd"]], [r["error"] for r in pa["hosvd"]], "x--",
                label="HOSVD (rank r, r, r)")
    for meth in ("Cℓ-PGD", "kℓ-PGD"):
        rr = [r for r in pa["local"] if r["method"] == meth]
        ax.semilogy([r["max_local"] for r in rr], [r["error"] for r in rr], "o-", color=cols[meth],
                    label=f"{meth} (max modes / sub-domain)")
    ax.set_xlabel("modes")
    ax.set_ylabel("relative L2 error at k = 0.05")
    ax.set_title("Fig. 3.12 (ours)")
    ax.legend(fontsize=7)
    ax = fig.add_subplot(1, 2, 2, projection="3d")
    H = np.asarray(pa["kpca"]["h"])
    T, Kk = np.meshgrid(np.linspace(0, 1, H.shape[0]), pa["k"], indexing="ij")
    ax.plot_surface(T, Kk, H, cmap="viridis")
    ax.set_xlabel("t")
    ax.set_ylabel("k")
    ax.set_title("Fig. 3.13 (ours): Hausdorff surface")
    fig.savefig(FIG / "fig3_12_13.png", dpi=100, bbox_inches="tight")
    plt.close(fig)
    names.append("fig3_12_13.png")

    # §3.5
    fig, ax = plt.subplots(1, 3, figsize=(15, 4))
    rows = cost_rows(res)
    labels = [f"{r['problem']}\n{r['method']}" for r in rows]
    for i, (k, lab) in enumerate((("offline_s", "offline time (s)"), ("online_ms", "online: full field (ms)"),
                                  ("storage", "numbers stored"))):
        ax[i].barh(range(len(rows)), [r[k] or 0 for r in rows])
        ax[i].set_yticks(range(len(rows)))
        ax[i].set_yticklabels(labels if i == 0 else [""] * len(rows), fontsize=6)
        ax[i].set_xscale("log")
        ax[i].set_title(lab)
    fig.savefig(FIG / "fig3_14_16.png", dpi=100, bbox_inches="tight")
    plt.close(fig)
    names.append("fig3_14_16.png")
    return names


def _best(rows, method, err=1e-4, update=True):
    ok = [r for r in rows if r["method"] == method and r.get("update", True) == update and r["error"] <= err]
    return min(ok, key=lambda r: r["total"]) if ok else None


def cost_rows(res: dict) -> list[dict]:
    rows = []
    ca = res["cantilever"]
    rows.append(dict(problem="cantilever", method="global PGD (6)", offline_s=ca["global_pgd_time_s"],
                     online_ms=ca["online_ms"]["global_pgd_6"], storage=ca["global_pgd_storage_6"]))
    c2 = ca["local"]["C"][1]
    rows.append(dict(problem="cantilever", method="Cℓ-PGD 9×2", offline_s=c2["offline_s"],
                     online_ms=ca["online_ms"]["C9x2"], storage=c2["storage"]))
    for key in ("heat_2pi7", "heat_5pi7"):
        hr = res[key]
        for gk in ("global_pgd", "global_pgd_update"):
            gg = hr["global"][gk]
            n = gg["modes_1e4"] or gg["modes"][-1]
            rows.append(dict(problem=key, method=gk.replace("_", " "), offline_s=gg["time_s"],
                             online_ms=gg["online_ms"], storage=n * gg["storage_per_mode"]))
        for meth in ("Cℓ-PGD", "MNOℓ-PGD", "kℓ-PGD"):
            b = _best(hr["local"], meth)
            if b:
                rows.append(dict(problem=key, method=meth + " (1e-4)", offline_s=b["offline_s"],
                                 online_ms=b["online_ms"], storage=b["storage"]))
    pa = res["parametric"]
    rows.append(dict(problem="parametric", method="global PGD (minimal residual)",
                     offline_s=pa["global_pgd"]["time_s"], online_ms=pa["global_pgd"]["online_ms"],
                     storage=pa["global_pgd"]["storage"]))
    for meth in ("Cℓ-PGD", "kℓ-PGD"):
        rr = [r for r in pa["local"] if r["method"] == meth]
        b = min(rr, key=lambda r: r["error"])
        rows.append(dict(problem="parametric", method=meth, offline_s=b["offline_s"], online_ms=b["online_ms"],
                         storage=b["storage"]))
    return rows


def report(res: dict, figs: list[str]) -> str:
    ca = res["cantilever"]
    L = ["# Local PGD (thesis ch. 3): our reproduction", "",
         "Regenerated by `./run bench local_pgd` (`benchmarks/local_pgd.py`; raw numbers in "
         "`benchmarks/results/local_pgd.json`). Code: `simreal_nodes/studies/ch3/local_pgd.py` "
         "(PGD, Cℓ / MNOℓ / kℓ partitions), "
         "`simreal_nodes/studies/ch3/problems.py` (full-order models). Errors: relative L2 over the grid against the "
         "full-order model (FOM) with the same discretisation. Every PGD stops on its own a-priori indicator "
         "(norm of the newest term over the norm of the sum); the FOM is only used to score.", "",
         "**Two PGD flavours.** *Plain greedy* (fixed point, no update) is what the thesis's global-PGD counts "
         "correspond to. *With update* (two-axis problems): after each enrichment the space modes are orthonormalised "
         "and all time functions recomputed by a reduced time stepping — the usual PGD projection step, much closer "
         "to POD-optimal. We report both because the comparison global vs local depends on it.", "",
         "## Full-order models", "",
         "- Heat: implicit Euler + linear elements vs the exact sine-series solution (`heat_series`): relative L2 "
         f"error {res['heat_5pi7']['fom_vs_series']:.2e} at N_x = 301, N_t = 401, "
         f"{res['heat_5pi7']['fom_vs_series_refined']:.2e} "
         f"with both steps halved (x_f = 5π/7; first order in Δt as expected). For x_f = 2π/7: "
         f"{res['heat_2pi7']['fom_vs_series']:.2e} → {res['heat_2pi7']['fom_vs_series_refined']:.2e}.",
         f"- Cantilever: Q1 plane stress, 90 × 10 elements; tip deflection {ca['fem_tip']:.4f} m vs Euler–Bernoulli "
         f"{ca['eb_tip']:.4f} m ({100 * ca['fem_tip_vs_eb']:.2f} % — shear flexibility, "
         "which beam theory ignores).", "",
         "## Mode counts beside the thesis", ""]
    rows = []
    for key, name in (("heat_2pi7", "2pi/7"), ("heat_5pi7", "5pi/7")):
        hr = res[key]
        g = hr["global"]
        row = dict(case=f"Idelsohn x_f = {name}", thesis_global=THESIS_GLOBAL_PGD_1E4[name],
                   pgd=g["global_pgd"]["modes_1e4"] or f">{g['global_pgd']['modes'][-1]}",
                   pgd_u=g["global_pgd_update"]["modes_1e4"], pod=g["global_pod"]["modes_1e4"])
        for meth, k in (("Cℓ-PGD", "c"), ("MNOℓ-PGD", "m"), ("kℓ-PGD", "k")):
            b = _best(hr["local"], meth)
            row[k] = f"{b['max_local']} / {b['total']} ({b['subdomains']})" if b else "—"
        rows.append(row)
    L.append(markdown_table(rows, [("case", "problem", "{}"), ("thesis_global", "thesis: global PGD", "{}"),
                                   ("pgd", "ours: global PGD (plain)", "{}"), ("pgd_u", "global PGD + update", "{}"),
                                   ("pod", "global POD", "{}"), ("c", "Cℓ max / total (sub-domains)", "{}"),
                                   ("m", "MNOℓ", "{}"), ("k", "kℓ", "{}")]))
    L += ["", "Modes to reach a relative L2 error of 1e-4 (ℓ-PGD: with update, the smallest total over "
              "the tolerances tried that reaches 1e-4; *max* = largest local basis, the thesis's measure in "
              "Fig. 3.10).", ""]
    c2 = ca["local"]["C"][1]
    L += [f"Cantilever: Cℓ-PGD with **2 load modes in 9 divisions** gives tip error {100 * c2['tip_vs_eb']:.2f} % vs "
          f"Euler–Bernoulli (FEM: {100 * ca['fem_tip_vs_eb']:.2f} %) and L2 error {c2['l2']:.2e}; global PGD needs "
          f"**{ca['global_modes_matching_C9x2']} modes** for the same L2 error and "
          f"{ca['global_modes_matching_C9x2_tip']} for the same tip error (thesis: 5–6). Global PGD and POD "
          "coincide on this 2D elliptic problem, as §3.1 says they must.", ""]
    L += ["## Where ours differ, and why", "",
          "- **x_f = 2π/7.** The issue fixes x_i = 2π/7, so x_f = 2π/7 is a *stationary* source: "
          "f(x, t) = g(x)·1(t_i<t<t_f) is rank one and the solution is nearly separable (POD needs "
          f"{res['heat_2pi7']['global']['global_pod']['modes_1e4']} modes for 1e-4). The thesis's 211 global modes "
          "imply a moving source in that case too (its x_i is not printed for it); we kept the stated parameters.",
          "- **x_f = 5π/7.** Our plain greedy PGD needs about as many modes as the thesis's (hundreds); with the "
          "update step it drops to the numbers in the table, close to POD. Against *plain* global PGD every ℓ-PGD "
          "variant needs far "
          "fewer modes per sub-domain (the thesis's claim); against updated global PGD the local bases are still "
          "several times smaller but their total is comparable — the saving is in the size of each local problem "
          "(time support of one sub-domain), i.e. offline time, not in the total count.",
          "- **MNOℓ-PGD** searches the sub-domain length by doubling + bisection instead of ±1 steps "
          "(same fixed point, fewer local solves).",
          "- **kℓ-PGD**: samples for k-PCA are blocks of 10–11 consecutive nodes of each particularization (the "
          "columns of Fig. 3.4b); the kernel is fitted on 1 500 seeded random blocks (reproducible), width by the "
          "median heuristic; sub-domains grow while the Hausdorff distance to the sub-domain's first k-PCA curve stays "
          "below ε (a fraction of the cloud's diameter), per partitioned axis — so it works on (t, k) boxes.",
          "- **Parametric case** at N_x = 151, N_t = 201, 26 conductivities k ∈ [0, 0.25] (Fig. 3.13's range) "
          "to keep the benchmark minutes long; the error is scored at k = 0.05 as in Fig. 3.12. Plain greedy PGD only "
          "(the update step is written for two axes).", ""]
    pa = res["parametric"]
    gal, mr = pa["global_pgd_galerkin"], pa["global_pgd"]
    L += ["**Global PGD on three axes.** Galerkin greedy PGD (the thesis's) on (x, t, k) "
          + (f"*diverges* here (error {gal['error'][-1]:.2g} after {gal['modes'][-1]} modes, worst "
             f"{max(gal['error']):.2g})" if gal["error"][-1] > 1.0 else
             f"reaches {gal['error'][-1]:.2g} after {gal['modes'][-1]} modes "
             f"(worst on the way {max(gal['error']):.2g})")
          + ": with the non-symmetric backward-difference time operator its terms minimise nothing, so nothing stops "
          "them from growing. The global baseline below is therefore *minimal-residual* PGD (Galerkin PGD on the "
          "normal equations AᵀA U = AᵀB, again a sum of Kronecker products; `pgd(..., residual=\"minimal\")`): "
          f"every term lowers the residual, and the error falls monotonically to {mr['error'][-1]:.2g} after "
          f"{mr['modes'][-1]} modes — slowly, since squaring the operator squares its condition number. The local "
          "boxes (short time support) are stable with Galerkin PGD.", ""]
    L += ["## Parametric heat (x, t, k)", "",
          markdown_table([dict(method="global PGD (minimal residual)", modes=pa["global_pgd"]["modes"][-1],
                               error=pa["global_pgd"]["error"][-1], storage=pa["global_pgd"]["storage"]),
                          dict(method="global PGD (Galerkin)", modes=pa["global_pgd_galerkin"]["modes"][-1],
                               error=pa["global_pgd_galerkin"]["error"][-1],
                               storage=pa["global_pgd_galerkin"]["storage"])]
                         + [dict(method=f"HOSVD r = {r['rank']}", modes=r["rank"], error=r["error"],
                                 storage=r["storage"])
                            for r in pa["hosvd"] if r["rank"] in (8, 16, 26, 40)]
                         + [dict(method=f"{r['method']} tol {r['tol']:g} ({r['subdomains']} boxes)",
                                 modes=f"{r['max_local']} / {r['total']}", error=r["error"], storage=r["storage"])
                            for r in pa["local"]],
                         [("method", "method", "{}"), ("modes", "modes (max / total)", "{}"),
                          ("error", "L2 error at k = 0.05", "{:.2e}"), ("storage", "numbers stored", "{}")]), ""]
    sw = res["heat_5pi7"].get("kpca_eps_sweep")
    if sw:
        L += ["## kℓ-PGD's knob: the Hausdorff threshold ε (x_f = 5π/7, tol 1e-4, no update)", "",
              markdown_table(sw, [("eps", "ε", "{:g}"), ("subdomains", "sub-domains", "{}"),
                                  ("max_local", "largest local basis", "{}"), ("total", "total modes", "{}"),
                                  ("error", "L2 error", "{:.2e}"), ("storage", "numbers stored", "{}"),
                                  ("offline_s", "offline (s)", "{:.1f}")]), "",
              "Small ε cuts wherever the k-PCA curve moves: many short sub-domains with tiny bases (the thesis's "
              "picture: the largest local basis falls from 200 to 6) and, at the same tolerance, a lower error, but "
              "more modes in total; large ε approaches global PGD. Storage stays within the same range. The knob "
              "trades the size of the largest local problem (the online cost of one sub-domain) against the "
              "number of sub-domains to store and switch between.", ""]
    L += ["## Time and memory (§3.5)", "",
          markdown_table(cost_rows(res), [("problem", "problem", "{}"), ("method", "method", "{}"),
                                          ("offline_s", "offline (s)", "{:.2f}"),
                                          ("online_ms", "online full field (ms)", "{:.2f}"),
                                          ("storage", "numbers stored", "{}")]), ""]
    L += ["## Figures", ""] + [f"![{f}](figures/{f})" for f in figs]
    m = machine()
    L += ["", f"Machine: {m.get('cpu', '?')}, {m['cpus']} CPUs, {m['date']}."]
    return "\n".join(L) + "\n"


def main():
    res = {}
    t0 = time.perf_counter()
    res["cantilever"] = bench_cantilever()
    print(f"cantilever done {time.perf_counter() - t0:.0f} s", flush=True)
    res["heat_2pi7"] = bench_heat("2π/7", 2 * np.pi / 7)
    print(f"heat 2pi/7 done {time.perf_counter() - t0:.0f} s", flush=True)
    res["heat_5pi7"] = bench_heat("5π/7", 5 * np.pi / 7)
    print(f"heat 5pi/7 done {time.perf_counter() - t0:.0f} s", flush=True)
    res["parametric"] = bench_parametric()
    print(f"parametric done {time.perf_counter() - t0:.0f} s", flush=True)
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "local_pgd.json").write_text(json.dumps({"benchmark": "local_pgd", "machine": machine(), **res},
                                                       indent=1, default=float))
    figs = figures(res)
    md = report(res, figs)
    (DOCS / "local_pgd.md").write_text(md)
    (RESULTS / "local_pgd.md").write_text(md.replace("](figures/", "](../../docs/figures/"))
    import shutil

    shutil.copy(FIG / "fig3_9_10_11_heat_5pi7.png", RESULTS / "local_pgd.png")
    print(md)


if __name__ == "__main__":
    main()
