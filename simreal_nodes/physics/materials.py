"""Constitutive laws as functions of the deformation gradient F (total Lagrangian).

Every tensor argument has shape (3, 3, ...) with any trailing (element, quadrature-point) dims,
as scikit-fem's forms deliver them. Each material gives

- ``P(F)``: first Piola-Kirchhoff stress, P = dW/dF,
- ``dP(F, H)``: its directional derivative dP/dF : H (the consistent tangent applied to H),
- ``energy(F)``: the stored energy density W (used to check P and dP by finite differences).

Laws (thesis references):
- :class:`LinearElastic`: sigma = lambda tr(eps) I + 2 mu eps, eps = sym(F - I) (small strain, §2.1.2).
- :class:`SaintVenantKirchhoff`: W = lambda/2 (tr E)^2 + mu E:E, E = (F^T F - I)/2 (§4.5.2, §5.4.1).
- :class:`NeoHookean`: W = mu/2 (I1 - 3) - mu ln J + lambda/2 (ln J)^2 (§4.5.4).
- :class:`NeoHookeanDecoupled`: W = kappa/4 (J^2 - 1 - 2 ln J) + C1 (J^(-2/3) I1 - 3), C1 = mu/2 — the
  deviatoric-invariant form of Eq. 5.9 (as printed, Eq. 5.9 is not stress free at F = I, so we use
  the standard decoupled form; it is also the law of the deal.II Cook-membrane reference).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np


class LockingWarning(UserWarning):
    """Nearly incompressible material on low-order elements (volumetric locking), or a beam on linear elements
    (shear locking in bending): expect displacements too small."""


# --- tensor helpers on (3, 3, ...) arrays ---------------------------------------------------

def eye_like(F):
    I = np.zeros_like(F)
    for i in range(F.shape[0]):
        I[i, i] = 1.0
    return I


def tr(A):
    return np.einsum("ii...->...", A)


def T(A):
    return np.swapaxes(A, 0, 1)


def mul(A, B):
    return np.einsum("ij...,jk...->ik...", A, B)


def ddot(A, B):
    return np.einsum("ij...,ij...->...", A, B)


def det3(F):
    return (F[0, 0] * (F[1, 1] * F[2, 2] - F[1, 2] * F[2, 1])
            - F[0, 1] * (F[1, 0] * F[2, 2] - F[1, 2] * F[2, 0])
            + F[0, 2] * (F[1, 0] * F[2, 1] - F[1, 1] * F[2, 0]))


def inv3(F):
    """Inverse of (3, 3, ...) arrays by cofactors; also returns det."""
    J = det3(F)
    C = np.empty_like(F)
    C[0, 0] = F[1, 1] * F[2, 2] - F[1, 2] * F[2, 1]
    C[0, 1] = F[0, 2] * F[2, 1] - F[0, 1] * F[2, 2]
    C[0, 2] = F[0, 1] * F[1, 2] - F[0, 2] * F[1, 1]
    C[1, 0] = F[1, 2] * F[2, 0] - F[1, 0] * F[2, 2]
    C[1, 1] = F[0, 0] * F[2, 2] - F[0, 2] * F[2, 0]
    C[1, 2] = F[0, 2] * F[1, 0] - F[0, 0] * F[1, 2]
    C[2, 0] = F[1, 0] * F[2, 1] - F[1, 1] * F[2, 0]
    C[2, 1] = F[0, 1] * F[2, 0] - F[0, 0] * F[2, 1]
    C[2, 2] = F[0, 0] * F[1, 1] - F[0, 1] * F[1, 0]
    return C / J, J


def sym(A):
    return 0.5 * (A + T(A))


def lame(E: float, nu: float) -> tuple[float, float]:
    """Lamé parameters (lambda, mu) from Young's modulus and Poisson's ratio (3D)."""
    return E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))


def von_mises(sigma):
    """von Mises equivalent stress of Cauchy stress tensors (3, 3, ...)."""
    s = sigma - tr(sigma) / 3.0 * eye_like(sigma)
    return np.sqrt(1.5 * ddot(s, s))


# --- materials ---------------------------------------------------------------------------------

@dataclass(frozen=True)
class Material:
    E: float
    nu: float
    name: str = "material"

    def __post_init__(self):
        if not (np.isfinite(self.E) and self.E > 0):
            raise ValueError(f"Young's modulus must be positive and finite, got {self.E}")
        if not (-1.0 < self.nu < 0.5):
            raise ValueError(f"Poisson's ratio must be in (-1, 0.5), got {self.nu}: nu = 0.5 is incompressible, "
                             "which a displacement-only formulation cannot represent")

    @property
    def lame_lambda(self) -> float:
        return lame(self.E, self.nu)[0]

    @property
    def lame_mu(self) -> float:
        return lame(self.E, self.nu)[1]

    @property
    def kappa(self) -> float:
        return self.E / (3 * (1 - 2 * self.nu))

    def scaled(self, factor: float) -> Material:
        """The same law with every modulus multiplied by ``factor`` (used to solve in E units)."""
        return type(self)(self.E * factor, self.nu, self.name)

    def check_locking(self, order: int) -> None:
        if self.nu > 0.45 and order == 1:
            warnings.warn(f"Poisson's ratio {self.nu} with linear elements locks volumetrically: displacements "
                          "will be too small; use order 2 elements (or nu <= 0.45)", LockingWarning, stacklevel=3)
        elif self.nu > 0.495:
            warnings.warn(f"Poisson's ratio {self.nu} is nearly incompressible: even quadratic elements lock; "
                          "results are stiffer than the truth", LockingWarning, stacklevel=3)

    def cauchy(self, F):
        """Cauchy stress sigma = J^-1 P F^T."""
        return mul(self.P(F), T(F)) / det3(F)

    def as_dict(self) -> dict:
        return {"law": self.law, "E": self.E, "nu": self.nu, "name": self.name}

    # to be provided by subclasses
    law = "abstract"

    def P(self, F):  # pragma: no cover
        raise NotImplementedError

    def dP(self, F, H):  # pragma: no cover
        raise NotImplementedError

    def energy(self, F):  # pragma: no cover
        raise NotImplementedError


class LinearElastic(Material):
    law = "linear_elastic"

    def P(self, F):
        eps = sym(F - eye_like(F))
        return self.lame_lambda * tr(eps) * eye_like(F) + 2 * self.lame_mu * eps

    def dP(self, F, H):
        e = sym(H)
        return self.lame_lambda * tr(e) * eye_like(H) + 2 * self.lame_mu * e

    def energy(self, F):
        eps = sym(F - eye_like(F))
        return 0.5 * self.lame_lambda * tr(eps) ** 2 + self.lame_mu * ddot(eps, eps)

    def cauchy(self, F):
        return self.P(F)  # small strain: no distinction


class SaintVenantKirchhoff(Material):
    law = "saint_venant_kirchhoff"

    def _S(self, F):
        E = 0.5 * (mul(T(F), F) - eye_like(F))
        return self.lame_lambda * tr(E) * eye_like(F) + 2 * self.lame_mu * E

    def P(self, F):
        return mul(F, self._S(F))

    def dP(self, F, H):
        dE = sym(mul(T(F), H))
        dS = self.lame_lambda * tr(dE) * eye_like(F) + 2 * self.lame_mu * dE
        return mul(H, self._S(F)) + mul(F, dS)

    def energy(self, F):
        E = 0.5 * (mul(T(F), F) - eye_like(F))
        return 0.5 * self.lame_lambda * tr(E) ** 2 + self.lame_mu * ddot(E, E)


class NeoHookean(Material):
    law = "neo_hookean"

    def P(self, F):
        Finv, J = inv3(F)
        FiT = T(Finv)
        return self.lame_mu * (F - FiT) + self.lame_lambda * np.log(J) * FiT

    def dP(self, F, H):
        Finv, J = inv3(F)
        FiT = T(Finv)
        lnJ = np.log(J)
        return (self.lame_mu * H + (self.lame_mu - self.lame_lambda * lnJ) * mul(mul(FiT, T(H)), FiT)
                + self.lame_lambda * tr(mul(Finv, H)) * FiT)

    def energy(self, F):
        J = det3(F)
        lnJ = np.log(J)
        return 0.5 * self.lame_mu * (ddot(F, F) - 3) - self.lame_mu * lnJ + 0.5 * self.lame_lambda * lnJ ** 2


class NeoHookeanDecoupled(Material):
    """W = kappa/4 (J^2 - 1 - 2 ln J) + mu/2 (J^(-2/3) I1 - 3)."""

    law = "neo_hookean_decoupled"

    def P(self, F):
        Finv, J = inv3(F)
        FiT = T(Finv)
        I1 = ddot(F, F)
        Jm23 = J ** (-2.0 / 3.0)
        return 0.5 * self.kappa * (J * J - 1) * FiT + self.lame_mu * Jm23 * (F - I1 / 3.0 * FiT)

    def dP(self, F, H):
        Finv, J = inv3(F)
        FiT = T(Finv)
        I1 = ddot(F, F)
        Jm23 = J ** (-2.0 / 3.0)
        trFiH = tr(mul(Finv, H))
        dFiT = -mul(mul(FiT, T(H)), FiT)
        dvol = self.kappa * J * J * trFiH * FiT + 0.5 * self.kappa * (J * J - 1) * dFiT
        dI1 = 2.0 * ddot(F, H)
        diso = self.lame_mu * (-2.0 / 3.0 * Jm23 * trFiH * (F - I1 / 3.0 * FiT)
                          + Jm23 * (H - dI1 / 3.0 * FiT - I1 / 3.0 * dFiT))
        return dvol + diso

    def energy(self, F):
        J = det3(F)
        return 0.25 * self.kappa * (J * J - 1 - 2 * np.log(J)) + 0.5 * self.lame_mu * (J ** (-2 / 3) * ddot(F, F) - 3)


LAWS = {c.law: c for c in (LinearElastic, SaintVenantKirchhoff, NeoHookean, NeoHookeanDecoupled)}


def make_material(law: str, E: float, nu: float, name: str = "material") -> Material:
    try:
        return LAWS[law](float(E), float(nu), name)
    except KeyError:
        raise ValueError(f"unknown material law '{law}' (known: {', '.join(LAWS)})") from None
