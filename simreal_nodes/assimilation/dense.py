"""Dense model-based measurement (``tracking.measurements: dense``): photometric alignment of the object's own
surface texture, the idea of digital image correlation carried through the reduced model.

Where the sparse tracker needs ORB keypoints on the object (none on a faint texture), this uses every pixel the
object covers. Points are sampled on the model's surface (object frame, rest shape) about ``step_px`` apart in the
reference view; their intensities in that view are the template. In a new image each sample sits where the model
deformed by mu puts it,

    X_k(theta) = c + R(omega) (T_map_obj (x_k + u_k(mu)) - c) + t                  (map frame)
    r_k(theta) = I(pi(T_cw X_k)) - (a I_ref,k + b + I_ref,k (n_k(mu) - n_k,ref) . g),   theta = (mu, omega, t, a, b, g),

with u_k(mu) = sum_i w_ki u(x_i, mu) interpolated in the surface triangle (Eq. 4.10's link, dense), pi the
camera, (omega, t) a small rigid correction of the object about its centre c (it absorbs the camera pose's drift
and the hand-measured anchor's error: a few mm, which is a pixel or two, as large as a faint deflection), (a, b)
an affine brightness change and g the shading change of a matte (Lambertian) surface whose normal turns as it
deforms: a surface point of albedo rho under ambient light and one distant light l shows rho (k_a + k_d n.l), so
a turn of its normal by dn changes its brightness by about I_ref k_d dn.l / (k_a + k_d n_ref.l) = I_ref dn.g (g
unknown, the same for the whole surface; n_k(mu) the deformed surface's normal at the sample, smooth across each
face of the model as a renderer shades it: :class:`SmoothNormals`). Without
it a faint texture's bending shows mostly as a change of shading, which no rigid or affine term explains and the
fit took for a deformation elsewhere (development plate seed 7: its load's position across the plate 14 % of its
range off). Gauss-Newton with Levenberg damping on Tukey's biweight cost of r (scale from
the median absolute residual, so an occluder such as the load itself counts nothing), the Jacobian through the PGD
sensitivities du/dmu (Eq. 4.11 with image gradients in place of the reprojection's), coarse to fine over an
image pyramid. mu stays in its box (projected steps, as :func:`lm.solve`); weak Gaussian priors hold the rigid
correction near zero along directions the image cannot see (translation along the viewing ray).

With a depth image (RGB-D), the rigid correction is split in two. The camera pose's error this frame, epsilon,
moves everything in the map; it is measured on the static surroundings as well: points in a ring around the
object's outline in the reference view, back-projected with their depth, whose residuals

    r_j(epsilon) = I(pi(T_cw (c + R(omega_e) (X_j - c) + t_e))) - (a_s I_ref,j + b_s)

enter the same robust cost. They cannot deform, so the camera's error is no longer free to trade against a bending
(a cantilever's tip moves much as a small rotation would). The object's own placement error rho comes on top
(the object moves by rho + epsilon): not fitted when the registration measured the placement from the same depth,
measured at rest and then held otherwise.

The template is taken once, in the first frame with a camera pose that shows enough of the object, in the state
the object is in there: at rest (zero displacement) unless that state was measured otherwise. With a depth image
the tracker measures it from the object's shape (:mod:`.depth_state`): a scene loaded from its first frame then
has its deformation in the template, not taken for the rest shape.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from simreal_nodes import geometry as G
from simreal_nodes.camera import CameraModel
from simreal_nodes.rom.model import DeformationView, ReducedModel

Array = NDArray[np.float64]
Grad = tuple[NDArray[np.float32], NDArray[np.float32]]  # d image / du, d image / dv
N_RIGID = 6  # omega (3), t (3)
TUKEY = 4.685  # biweight threshold in robust standard deviations (95 % efficiency under Gaussian noise)


GRID_BRIGHTNESS = ("auto", "always", "never")  # DenseSettings.grid_brightness


@dataclass
class DenseSettings:
    """What the dense measurement trades (each measured in benchmarks/family.py's dense rows)."""

    step_px: float = 1.5  # sample spacing in the reference view (pixels): finer = more samples, slower
    levels: int = 3  # pyramid levels (coarse levels reach larger motions)
    finest: int = 0  # the finest level fitted (1: half resolution, where blur and aliasing weigh less)
    max_samples: int = 20000
    min_samples: int = 200  # fewer visible samples: no measurement
    iterations: int = 8  # at most, per level
    tolerance: float = 2e-3  # converged when an iteration lowers the cost by less than this fraction
    rigid: bool = True  # estimate the rigid correction (omega, t)
    # 1-sigma of the rigid correction's prior (about zero): the camera's drift and the placement's error, a few
    # mm; the correction is also bounded at 3 sigma (a fit at rest that turned the object by degrees to explain a
    # bending it cannot model would otherwise run away)
    prior_rot_rad: float = np.deg2rad(0.5)
    prior_trans_m: float = 0.005
    # once a frame at rest has measured the correction (the anchor's error as the images see it), a deformed
    # fit keeps its rotation within this of it and its translation within held_trans_m (the camera's drift): a
    # free rotation would take the blame for a cantilever's bending
    held_rot_rad: float = np.deg2rad(0.1)
    held_trans_m: float = 0.003
    grid: int = 32  # coarse search over mu at the coarsest level every frame (0: off)
    # how the grid's candidates are compared: "always" with the object's brightness (a, b, g) fitted to each (the
    # profile of the cost, as :meth:`DenseAligner._refine` does); "never" at the warm start's brightness (the last
    # frame's); "auto" fitted only when the warm start's gain is under min_gain (a misaligned frame left it stale:
    # at that brightness the candidates differ by the spurious shading rather than by how the texture lines up),
    # else at the warm start's. "always" mended development seed 0 at 65 degrees of azimuth but let seed 1 at 80
    # degrees pick wrong candidates (OK frames' p90 0.34 -> 9.8 % of the span): with its brightness free, a
    # misplaced candidate at the coarsest level can explain the image nearly as well
    grid_brightness: str = "auto"
    # the static surroundings (RGB-D: a ring around the object's outline in the reference view, back-projected
    # with its depth) measure the camera's error apart from the object's; 0: off (the object alone)
    static_ring_px: float = 32.0
    static_margin_px: float = 4.0  # gap between the outline and the ring (the object's edge, a load on it)
    static_share: float = 0.5  # at most this many surroundings samples per object sample (time per frame)
    # the object's pose was measured from the depth images (``anchor: registration``): with the surroundings in
    # the fit, no placement correction of the object on top of the camera's (see :meth:`DenseAligner.solve`)
    placement_measured: bool = False
    min_grazing: float = 0.25  # |cos| of the viewing angle below which a surface sample is not used
    # after Gauss-Newton, a search of the cost over each free mu within this share of its range about the
    # solution (finest level; at most three free parameters); False: Gauss-Newton alone
    refine: bool = True
    refine_span: float = 0.1
    # with surroundings: the camera's error measured on them alone first, then held in the object's fit; False
    # (the default, better on development seeds 12-49): both in one joint fit
    camera_first: bool = False
    # with surroundings in the joint fit: refit the camera's error on the surroundings alone from the joint fit's,
    # and report how far (Mahalanobis, in the correction's prior sigmas) they move it (DenseResult.debug
    # 'camera_gap_sigma'); the tracker flags a fit whose gap exceeds max_camera_gap: the joint fit traded the
    # camera's error against the object's deformation (a camera 5 degrees above the floor, development seed 1: 8.7 %
    # of the span off, every frame OK before). 1.0 was chosen on development seeds 0-5 as drawn, seed 0 from 2 m
    # and at 65 degrees of elevation, seed 1 from 2 m and at 5 and 80 degrees: the good views stay under 0.65 but
    # for seed 1 at 2 m (3.0 at most, a third of its frames over 1); the failing view's bad frames are all over 1
    # (median 3.9; benchmarks/flag_calibration.py). It costs one more fit, on the
    # surroundings alone, per frame: the tracker's time on development seed 3 went from 66 to 81 ms per
    # frame (False: `tracking.dense_camera_check`); it changes no estimate, only its state. A frame whose
    # surroundings are too few for a fit of their own (under min_samples / 4^level at every level) is not checked
    # (the gap is NaN)
    camera_check: bool = True
    max_camera_gap: float = 1.0
    # the tracker flags a fit whose brightness gain (a: the share of the reference's texture contrast the image
    # shows where the fit put the samples) is under this: a misaligned fit sees the texture decorrelated and
    # explains the image by its mean (development seed 0 seen at 65 degrees of azimuth, after the camera was lost:
    # gain -0.06 to 0.11 on its 4 frames more than 2 % of the span off; development beam 14: -0.36 on one). 0.5 lies
    # between those and the 2630 frames within 2 % of the development beams 0-19 and of 18 views of seeds 0 and 1
    # (grazing, from 0.5-2 m, 16 grey levels of noise, 4 px of blur): their gain is 0.77 at the least
    # (`python -m benchmarks.flag_calibration --gain`). It catches a fit that lost the texture, not every wrong one
    # (5 of those views' and beams' 240 frames more than 2 % off; rerun in stop 49). It changes no estimate of a
    # frame, only its state (and so whether its shading is fused)
    min_gain: float = 0.5
    # the other basin at full detail: where the coarse search's runner-up from another basin (``grid_margin``)
    # costs less than this share more than its winner, the fit is run a second time from the runner-up (every level,
    # then the search of the cost) and the cheaper of the two at the finest level is kept. The coarsest level sees
    # a small load's bending at a quarter of its size, too little to tell a load over one support from the same
    # load over the other (development seed 9), and once picked, the finer levels only polish that basin; 0: off.
    # It costs a second fit on the frames it runs on (9.5 % of the development frames have a margin under 0.1; set
    # from those frames' margins before any run with it: development seed 9's frames at the wrong support read
    # 0.013-0.072). Development seed 9: p90 99.5 % -> 0.47 % of the span; docs/tracking.md
    basin_check: float = 0.1
    # the tracker flags a fit whose other basin's fit (``basin_check``) ended more than ``ambiguity_apart`` of a range
    # away (any free parameter) and costs less than ``max_ambiguity_gap`` more at the finest level: two loads explain
    # the image alike, and which one was kept is a coin toss (a view or a texture that cannot place the load:
    # tests/assimilation/test_dense.py's mirror-symmetric stretch). Held-out beam 1041's six frames 55-58 % of the span
    # off, taken for such ties in stop 57, are not: both fits ended in the same wrong basin (the other within 0.01 of a
    # range of the kept one), which no comparison of the two can flag (docs/tracking.md). Set on the development beams
    # 0-19 (``python -m benchmarks.flag_calibration --ambiguity``): of their 224 frames with a second fit, 150 ended
    # within 0.02 of a range of the kept one (a fall back into its basin, however close the cost: not an ambiguity) and
    # 72 more than 0.1 away, whose gaps are 0.187 at the least (71 of them within 2 % of the span; seed 14's frame 39,
    # 40 % off, has 0.80 and was flagged for its gain): 0.01 flags none of them and leaves a factor of about 20. The
    # development beams hold no ambiguous frame, so what it catches is measured on held-out seeds only. It changes no
    # estimate, only its state (and so whether its shading is fused); 0: no flag
    max_ambiguity_gap: float = 0.01
    # the tracker flags a fit where a tracked parameter's standard deviation (the normal equations scaled by the
    # residual) exceeds this share of its range (:func:`~simreal_nodes.assimilation.tracker.loosely_held`): the
    # images hold it too loosely to vouch for (a shelf's s_y). Set on the development beams 0-19 and 24 development
    # plates (stop 76's reruns, before the flag; ``python -m benchmarks.flag_calibration --std``): 1 % flags 487 of the
    # plates' 781 frames more than 2 % off: all of those of the shelves whose s_y is over 3 % off (1, 13, 15, 21, 28)
    # but 16's (51 of 59) and 29's (2.95 %: 9 of 39); 105 of their 1081 OK frames within 2 %; none of the beams' 1465
    # OK frames within 2 %
    # (their OK frames' std: median 0.08 %, at most 0.86 %). 1.5 % would miss most frames of 13, 15 and 16. It changes
    # no estimate, only its state, after the shading is fused; 0: no flag
    max_std_frac: float = 0.01
    # with ``basin_check``: where the warm start (the last frame's estimate) lies more than a quarter of a range from
    # where both the winner's and the runner-up's fits ended, fit from it as well (a third fit) and keep the cheapest:
    # the coarse search can lead both into one wrong basin while the last frame's is right (held-out beam 1041, stop
    # 58: six frames read at 0.14 for 0.33, both fits there, the frames before and after at 0.33); False: two fits.
    # Off by default since stop 59: on the 50 development beams the third fit was kept on 7 frames; it moved no loaded
    # frame's estimate by more than 0.011 of a range and helped none (benchmarks/results/family_dev_warm_off.md);
    # its only gain is 1041, the held-out scene that prompted it (a knob that helps one scene is a knob)
    basin_warm: bool = False
    ambiguity_apart: float = 0.1
    # the shading change of the deforming surface (g in the module docstring; False: the affine brightness alone)
    # and the 1-sigma of g's prior about zero (brightness fraction per unit change of the normal: k_d / k_a is at
    # most a few for a matte surface; the prior only holds the component along the normal, which no turn sees)
    shading: bool = True
    prior_shading: float = 1.0
    # g is a property of the light and the object, the same in every frame: what each frame measures of it (its
    # information with every other unknown of that frame marginalised out) is fused over about this many frames
    # that the tracker judged sound (exponential forgetting, 1 - 1/n per accepted frame; :meth:`accept_shading`)
    # into the next frames' prior, so that a frame whose deformation is barely seen cannot pass its signal off as
    # shading; 0: each frame's g alone, under the prior above
    shading_frames: int = 50
    # the template is one image, and its noise is in every later comparison: the same error on every frame, which
    # no number of frames averages out (development plate 1 rendered with a noiseless reference frame: s_y 11.5 ->
    # 7.6 % of its range). Each frame the tracker judges at rest before any deformation was seen (the frames that
    # also measure the placement error, :meth:`DenseAligner.hold_rest`) is aligned to the template at the reference
    # state and its intensities, brought to the template's brightness, are averaged into it (the surroundings' too),
    # up to this many frames in all; 0: the first view alone (:meth:`DenseAligner.refine_template`). The default
    # since stop 78 (docs/family.md), with the stop below: development beams 0-19 p90 of the scene medians 1.07 ->
    # 0.79 %, stop 77's 24 development plates 7.20 -> 4.69 % (without the stop; rerun with it, plates 0-4 and 17
    # level or better, 21 20.0 -> 22.5 %, a failure with either template)
    template_frames: int = 20
    # a load too small to pass as a deformation still bends the object a little, and a view of it averaged into the
    # template puts that bend into every later comparison (development cantilevers 4 and 8: their first load near
    # the clamp was judged "no measurable deformation" for 16 frames, 5 of them averaged in; the deformed fit's
    # image motion there rose from 0.14 to 0.22-0.36 px). The averaging closes for good at the first view whose
    # deformed fit moves the image more than this many pixels beyond the least motion of the views so far (at rest
    # it varied by 0.013 px at most on development plates 13 and 21 and cantilever 4)
    template_motion_px: float = 0.05

    def __post_init__(self) -> None:
        if self.grid_brightness not in GRID_BRIGHTNESS:
            raise ValueError(f"DenseSettings.grid_brightness must be one of {', '.join(GRID_BRIGHTNESS)}, "
                             f"not {self.grid_brightness!r}")


@dataclass
class SurfaceSamples:
    """Points on the model surface: rest positions (object frame), their triangle's corners and barycentric
    weights (for the displacement), and the triangle normal (for visibility)."""

    x: Array  # (N, 3)
    nodes: NDArray[np.int64]  # (N, 3)
    weights: Array  # (N, 3)
    normal: Array  # (N, 3) unit; orientation not assumed (visibility uses |cos| and a depth buffer)
    face: NDArray[np.int64]  # (N,) the sample's triangle in model.surface


def sample_surface(model: ReducedModel, spacing: float, max_samples: int, seed: int = 0) -> SurfaceSamples:
    """About one sample per ``spacing``^2 of surface (stochastic rounding per triangle, seeded), at most
    ``max_samples`` (the spacing grows to fit)."""
    V, F = np.asarray(model.points, np.float64), np.asarray(model.surface, np.int64)
    A, B, C = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    cr = np.cross(B - A, C - A)
    area = 0.5 * np.linalg.norm(cr, axis=1)
    spacing = max(spacing, float(np.sqrt(area.sum() / max(max_samples, 1))))
    rng = np.random.default_rng(seed)
    want = area / spacing**2
    count = np.floor(want + rng.random(len(F))).astype(np.int64)
    tri = np.repeat(np.arange(len(F)), count)
    r1, r2 = np.sqrt(rng.random(len(tri))), rng.random(len(tri))
    w = np.c_[1 - r1, r1 * (1 - r2), r1 * r2]
    x = w[:, :1] * A[tri] + w[:, 1:2] * B[tri] + w[:, 2:] * C[tri]
    n = cr[tri] / np.maximum(np.linalg.norm(cr[tri], axis=1, keepdims=True), 1e-300)
    return SurfaceSamples(x, F[tri], w, n, tri)


def pyramid(gray: NDArray[np.generic], levels: int) -> list[NDArray[np.float32]]:
    """Gaussian pyramid (level 0 = the image) as float32."""
    out = [np.asarray(gray, np.float32)]
    for _ in range(1, levels):
        out.append(np.asarray(cv2.pyrDown(out[-1]), np.float32))
    return out


def _gradients(pyr: list[NDArray[np.float32]]) -> list[Grad]:
    """Each level's image gradients by central differences, [-1, 0, 1] / 2."""
    return [(np.asarray(cv2.Sobel(p, cv2.CV_32F, 1, 0, ksize=1, scale=0.5), np.float32),
             np.asarray(cv2.Sobel(p, cv2.CV_32F, 0, 1, ksize=1, scale=0.5), np.float32)) for p in pyr]


def _at_level(uv: Array, level: int) -> Array:
    """Full-resolution pixel coordinates -> coordinates in pyramid level ``level`` (pixel centres kept)."""
    s = 0.5**level
    out: Array = (uv + 0.5) * s - 0.5
    return out


_REMAP_COLS = 32000
_CANDIDATES = 64  # candidates costed in one pass at most


def bilinear(img: NDArray[np.float32], uv: Array) -> NDArray[np.float32]:
    """Bilinear samples of ``img`` at (N, 2) pixel coordinates; outside the image: NaN.

    The samples are one row of OpenCV's map, not one column: ``remap`` shares its rows among OpenCV's threads, and
    a few thousand samples split into stripes cost more in the threads' wake-ups than they save (one row: the
    tracker's time per frame 0.93 of it on development scenes 0, 3 and 12, every estimate the same to the bit;
    ``benchmarks/results/dense_budget.md``, stop 95)."""
    if uv.size == 0:
        return np.zeros(0, np.float32)
    if len(uv) > _REMAP_COLS:  # OpenCV's maps hold fewer than 2^15 columns: in pieces (each sample its own lookup)
        return np.concatenate([bilinear(img, uv[k:k + _REMAP_COLS]) for k in range(0, len(uv), _REMAP_COLS)])
    m = np.ascontiguousarray(uv.reshape(1, -1, 2), np.float32)
    v = cv2.remap(img, m, None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,  # type: ignore[call-overload]
                  borderValue=np.nan)
    return np.asarray(v, np.float32).reshape(-1)


def _median(a: Array) -> float:
    """``np.median`` of a 1-D array, the same value (NaN if any is NaN) without its generality's overhead (the
    robust scale takes two a Gauss-Newton iteration, most of them on a few hundred samples)."""
    n = a.shape[0]
    if n == 0:
        return float("nan")
    h = n // 2
    p = np.partition(a, (h, n - 1) if n % 2 else (h - 1, h, n - 1))
    if np.isnan(p[-1]):
        return float("nan")
    return float(p[h] if n % 2 else (p[h - 1] + p[h]) / 2)


def _cross(a: Array, b: Array) -> Array:
    """Row-wise cross product of (N, 3) arrays (np.cross's arithmetic, without its generality's overhead)."""
    out = np.empty(a.shape)
    out[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    out[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    out[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return out


def _unit(v: Array) -> Array:
    out: Array = v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-300)
    return out


@dataclass
class SmoothNormals:
    """The normals of a deforming surface at sample points, smooth across the triangles of one face of the
    object (as a renderer shades a curved surface), not across its edges: at each corner of a sample's triangle,
    the area-weighted sum of the normals of the triangles around that corner that lie within the crease angle of
    the sample's own, oriented alike; at the sample, the corners' normals blended by its barycentric weights
    (not normalised again: on a smooth face the blend's length differs from 1 by the square of the angle between
    the corners' normals, and the shading uses only its change since the reference view, where the same holds).

    ``nodes`` are the surface nodes involved, ``tris`` (T, 3) the triangles around the samples' corners (indices
    into ``nodes``), ``blend`` a sparse (3 F, T) matrix of +-1 (F: the samples' distinct triangles) that sums
    their raw cross products into each (triangle, corner) normal, ``slot`` (M,) a sample's triangle among the F."""

    nodes: NDArray[np.int64]
    rest: Array  # (C, 3) rest positions of ``nodes``
    view: DeformationView
    tris: NDArray[np.int64]
    blend: Any
    slot: NDArray[np.int64]
    weights: Array  # (M, 3)
    corner_ref: Array  # (3 F, 3) the corners' normals in the reference view's state (set by :meth:`set_reference`)
    # the last two corners() (a solve asks again for the mu it accepted)
    cache: dict[bytes, Array] = field(default_factory=dict, repr=False)
    # the barycentric blend as a sparse (M, 3 F) matrix (built on first use by :meth:`blend_rows`)
    _blend_samples: Any = field(default=None, init=False, repr=False, compare=False)

    @classmethod
    def build(cls, model: ReducedModel, face: NDArray[np.int64], weights: Array, towards: Array,
              n_modes: int | None, crease_deg: float = 45.0) -> SmoothNormals:
        """For samples on triangles ``face`` (indices into model.surface) with barycentric ``weights``; each
        sample's triangle is oriented to face ``towards`` (M, 3): a point on the side it is seen from."""
        from scipy.sparse import csr_matrix

        V, F = np.asarray(model.points, np.float64), np.asarray(model.surface, np.int64)
        uniq, slot = np.unique(face, return_inverse=True)
        cross = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
        unit = _unit(cross)
        # the orientation of each distinct sample triangle: towards the side it was seen from (mean over samples)
        centre = V[F[uniq]].mean(axis=1)
        look = np.zeros((len(uniq), 3))
        np.add.at(look, slot, towards - centre[slot])
        sign_f = np.where(np.sum(unit[uniq] * look, axis=1) < 0, -1.0, 1.0)
        # the triangles around each node
        order = np.argsort(F.ravel(), kind="stable")
        tri_of = order // 3
        starts = np.searchsorted(F.ravel()[order], np.arange(len(V) + 1))
        cos_crease = np.cos(np.deg2rad(crease_deg))
        rows, cols, vals = [], [], []
        for k, f in enumerate(uniq):
            nf = unit[f] * sign_f[k]
            for c in range(3):
                around = tri_of[starts[F[f, c]]:starts[F[f, c] + 1]]
                dots = unit[around] @ nf
                keep = np.abs(dots) >= cos_crease
                rows.append(np.full(int(keep.sum()), 3 * k + c))
                cols.append(around[keep])
                vals.append(np.sign(dots[keep]))
        r, t, v = np.concatenate(rows), np.concatenate(cols), np.concatenate(vals)
        used, t_local = np.unique(t, return_inverse=True)
        nodes, tri_local = np.unique(F[used], return_inverse=True)
        blend = csr_matrix((v, (r, t_local)), shape=(3 * len(uniq), len(used)))
        out = cls(nodes, V[nodes], model.deformation_view(nodes, n_modes), tri_local.reshape(-1, 3).astype(np.int64),
                  blend, slot.astype(np.int64), np.asarray(weights, np.float64), np.zeros((3 * len(uniq), 3)))
        out.set_reference(None)
        return out

    def corners(self, mu: Array | None) -> Array:
        """The unit normals (3 F, 3) (object frame) at the samples' triangles' corners of the surface deformed by
        ``mu`` (None: the rest shape)."""
        key = b"" if mu is None else np.asarray(mu, np.float64).tobytes()
        cache = self.cache
        if key in cache:
            return cache[key]
        X = self.rest if mu is None else self.rest + self.view.field.evaluate(mu)
        t = self.tris
        out = _unit(np.asarray(self.blend @ _cross(X[t[:, 1]] - X[t[:, 0]], X[t[:, 2]] - X[t[:, 0]])))
        if len(cache) >= 2:
            cache.pop(next(iter(cache)))
        cache[key] = out
        return out

    def corners_many(self, mus: Array) -> Array:
        """:meth:`corners` for each row of ``mus`` (K, n_mu): (K, 3 F, 3), the same arithmetic in one pass (not
        cached)."""
        X = self.rest + self.view.field.evaluate_many(mus)  # (K, C, 3)
        t = self.tris
        K, T = len(X), len(t)
        a = (X[:, t[:, 1]] - X[:, t[:, 0]]).reshape(K * T, 3)
        b = (X[:, t[:, 2]] - X[:, t[:, 0]]).reshape(K * T, 3)
        cr = _cross(a, b).reshape(K, T, 3).transpose(1, 0, 2).reshape(T, 3 * K)
        n = np.asarray(self.blend @ cr).reshape(self.blend.shape[0], K, 3).transpose(1, 0, 2)  # (K, 3 F, 3)
        out: Array = _unit(n.reshape(-1, 3)).reshape(n.shape)
        return out

    def set_reference(self, mu: Array | None) -> None:
        self.corner_ref = self.corners(mu).copy()

    def blend_rows(self, per_corner: Array, rows: NDArray[np.int64] | None = None) -> Array:
        """A per-corner quantity (3 F, ...) at the samples ``rows`` (None: all), by their barycentric weights."""
        if self._blend_samples is None:
            from scipy.sparse import csr_matrix

            m = len(self.slot)  # each row: the sample's three corners, in order (the sum as w0 a + w1 b + w2 c)
            cols = 3 * self.slot[:, None] + np.arange(3)
            self._blend_samples = csr_matrix((self.weights.ravel(), cols.ravel(), np.arange(0, 3 * m + 1, 3)),
                                             shape=(m, 3 * (int(self.slot.max()) + 1 if m else 0)))
        out: Array = np.asarray(self._blend_samples @ per_corner)
        return out if rows is None else out[rows]

    def at(self, mu: Array | None, rows: NDArray[np.int64] | None = None) -> Array:
        """The normals (M, 3) of the samples ``rows`` (None: all) of the surface deformed by ``mu``."""
        return self.blend_rows(self.corners(mu), rows)

    def change(self, mu: Array | None, rows: NDArray[np.int64] | None = None) -> Array:
        """n(mu) - n_ref (M, 3) at the samples ``rows`` (None: all)."""
        return self.blend_rows(self.corners(mu) - self.corner_ref, rows)


@dataclass
class Level:
    """The template at one pyramid level: its samples' rest positions, normals, displacement view and
    intensities in the reference view."""

    x: Array  # (M, 3) object frame
    normal: Array  # (M, 3) object frame
    view: DeformationView
    values: NDArray[np.float64]  # (M,) reference intensities at this level
    # the samples' normals as the object deforms (the shading; object frame, turned towards the reference camera)
    normals: SmoothNormals


@dataclass
class DenseResult:
    mu: Array
    cov_mu: Array  # (n_mu, n_mu); NaN where a parameter was not free
    rms: float  # robust residual scale of the fit (intensity levels, 1.4826 MAD)
    rest_rms: float  # the same with zero displacement (rigid correction and brightness refitted)
    used: int  # samples in the finest level's fit
    inliers: int  # of them within the biweight threshold
    motion_px: float  # 90th percentile of the image motion the fitted deformation makes
    iterations: int
    reason: str = ""
    debug: dict[str, float] = field(default_factory=dict)


class _Fit:
    """One Gauss-Newton / Levenberg solve over the levels (the deformed or the rest configuration).

    The rigid nuisance has two parts. ``cam`` (epsilon): the camera pose's error this frame, a rigid motion of
    everything in the map, measured on the static surroundings (and the object). ``rigid`` (rho): the object's
    own placement error on top of it, measured while the object is at rest; once held, a deformed fit does not
    move it. The object moves by rho + epsilon, the surroundings by epsilon alone."""

    def __init__(self, mu: Array | None, free: NDArray[np.bool_], rigid: Array, cam: Array, photo: Array,
                 photo_s: Array, prior: tuple[Array, Array], rho_free: bool, cam_free: bool) -> None:
        self.mu = None if mu is None else mu.copy()
        self.free = free
        self.rigid = rigid.copy()
        self.cam = cam.copy()
        self.photo = photo.copy()
        self.photo_s = photo_s.copy()  # the surroundings' brightness (another surface, another shading)
        self.prior = prior  # (mean, 1-sigma) of rho, (6,) each; epsilon's prior is the wide one about zero
        self.rho_free = rho_free
        self.cam_free = cam_free
        self.iterations = 0

    def copy(self) -> _Fit:
        return _Fit(self.mu, self.free, self.rigid, self.cam, self.photo, self.photo_s, self.prior, self.rho_free,
                    self.cam_free)

    @property
    def total(self) -> Array:
        """The object's whole rigid correction (rho + epsilon)."""
        out: Array = self.rigid + self.cam
        return out


@dataclass
class StaticLevel:
    """The static surroundings at one pyramid level: map-frame points back-projected from the reference depth
    image and their intensities in the reference view."""

    X: Array  # (M, 3) map frame
    values: NDArray[np.float64]


@dataclass
class _Chain:
    """The projection's derivatives at N points, kept to be chained with the image gradients there: for a point
    X = c + R(omega) d + t (map frame; ``d0`` = R(omega) d, ``Xc`` its camera-frame position, ``R_cw`` the camera's
    rotation) and, for the object's samples, d = R_mo (x + u(mu)) + ... with ``du`` = du/dmu (N, 3, n_mu).

    For image gradients g (n, 2) at the points ``sel``, v = g^T d(pixel)/dX (n, 3) is a row vector per point, and
    d(intensity)/d(omega) = d0 x v (a left increment moves X by omega x d0), d/dt = v, d/dmu = v R(omega) R_mo du:
    each a product of (n, 3) rows, never the (n, 2, p) pixel Jacobian itself."""

    Xc: Array
    d0: Array
    R_cw: Array
    Rr: Array
    fx: float
    fy: float
    du: Array | None = None
    R_mo: Array | None = None

    def __call__(self, g: Array, sel: NDArray[np.bool_]) -> Array:
        """d(intensity)/d(mu, omega, t) (n, n_mu + 6) at the points ``sel`` (a mask) with image gradients g there."""
        Xc, z = self.Xc[sel], self.Xc[sel, 2]
        gu, gv = g[:, 0] * self.fx / z, g[:, 1] * self.fy / z
        v = np.stack([gu, gv, -(gu * Xc[:, 0] + gv * Xc[:, 1]) / z], axis=1) @ self.R_cw
        cols = [_cross(self.d0[sel], v), v]
        if self.du is not None:
            assert self.R_mo is not None
            cols.insert(0, np.einsum("nc,ncp->np", v @ (self.Rr @ self.R_mo), self.du[sel]))
        return np.concatenate(cols, axis=1)


class DenseAligner:
    """One object's dense measurement: the template and the current rigid / brightness nuisances."""

    def __init__(self, model: ReducedModel, T_map_obj: Array, cam: CameraModel, n_modes: int | None,
                 settings: DenseSettings | None = None) -> None:
        self.model = model
        self.cam = cam
        self.K = cam.K
        self.T_mo = np.asarray(T_map_obj, np.float64)
        self.s = settings or DenseSettings()
        self.n_modes = n_modes
        self.levels: list[Level] = []
        self.static: list[StaticLevel] = []  # empty: no depth in the reference view (the object alone)
        # the views averaged into the template (:meth:`refine_template`) and each sample's count of them
        self.template_views = 0
        self.template_closed = False  # a view moved beyond the rest state's motion: no more averaging
        self._rest_motion = float("inf")  # the least image motion of the deformed fit in the views averaged
        self._counts: list[Array] = []
        self._static_counts: list[Array] = []
        self._mu_ref: Array | None = None
        self.rigid = np.zeros(N_RIGID)  # rho of the last fit: the next frame's start
        self.cam_corr = np.zeros(N_RIGID)  # epsilon of the last fit
        self.rest_rigid = np.zeros(N_RIGID)  # the same for the zero-displacement fit
        self.rest_cam = np.zeros(N_RIGID)
        # the object's brightness (a, b[, g]: 3 more with the shading) and the surroundings' (a_s, b_s)
        self.n_photo = 5 if self.s.shading else 2
        self.photo = self._photo0()
        self.photo_s = np.array([1.0, 0.0])
        self.rest_photo = self._photo0()
        self.rest_photo_s = np.array([1.0, 0.0])
        self.held: Array | None = None  # rho measured at rest (see :meth:`hold_rest`)
        # g's information and information-weighted sum fused over frames (:attr:`DenseSettings.shading_frames`)
        self.g_info = np.zeros((3, 3))
        self.g_eta = np.zeros(3)
        self.g_frame: tuple[Array, Array] | None = None  # the last solve's (information, its sum), not yet fused
        self._g_prior_memo: tuple[tuple[float, bytes, bytes], tuple[Array, Array]] | None = None
        self._wide_memo: tuple[tuple[float, float], Array] | None = None
        self._taken: list[tuple[Array, NDArray[np.int64], Array]] = []  # (array, rows, array[rows]): _take
        self.grid_margin = float("nan")  # the last coarse search's runner-up margin (see :meth:`_grid_start`)
        self.grid_runner_up: Array | None = None  # and that runner-up's parameters
        self.c = G.transform(self.T_mo, np.asarray(model.points, np.float64).mean(axis=0, keepdims=True))[0]
        self._rot_cache: dict[bytes, Array] = {}
        # images are undistorted once per frame (one remap) so that the hot loop projects with the pinhole alone
        self._maps = None
        if cam.has_distortion:
            self._maps = cam.undistort_maps(cam.K, (cam.width, cam.height), cv2.CV_32FC1)

    def _photo0(self) -> Array:
        out: Array = np.r_[1.0, np.zeros(self.n_photo - 1)]
        return out

    def ideal(self, gray: NDArray[np.generic], nearest: bool = False) -> NDArray[np.float32]:
        """The image as the pinhole camera of the same K would see it (float32); ``nearest`` for a depth image
        (no blending across a depth edge)."""
        g = np.asarray(gray, np.float32)
        if self._maps is None:
            return g
        return np.asarray(cv2.remap(g, self._maps[0], self._maps[1], cv2.INTER_NEAREST if nearest else
                                    cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=np.nan), np.float32)

    @property
    def has_template(self) -> bool:
        return bool(self.levels)

    # -- the template ---------------------------------------------------------------------------------------
    def visible(self, T_cw: Array, X_map: Array, normal_map: Array) -> NDArray[np.bool_]:
        """Samples in front of the camera, inside the image, not seen edge-on and nearest in a coarse depth
        buffer (2-pixel cells): the back faces and whatever the object hides of itself drop out."""
        Xc = X_map @ T_cw[:3, :3].T + T_cw[:3, 3]
        uv = self.cam.project(Xc, distort=False)
        ok: NDArray[np.bool_] = np.all(np.isfinite(uv), axis=1) & (Xc[:, 2] > 0)
        ok &= (uv[:, 0] >= 1) & (uv[:, 1] >= 1) & (uv[:, 0] <= self.cam.width - 2) & (uv[:, 1] <= self.cam.height - 2)
        view = Xc / np.maximum(np.linalg.norm(Xc, axis=1, keepdims=True), 1e-12)
        cosang = np.abs(np.sum((normal_map @ T_cw[:3, :3].T) * view, axis=1))
        ok &= cosang >= self.s.min_grazing
        if not ok.any():
            return ok
        cell = 2.0
        cw = int(self.cam.width / cell) + 1
        key = (uv[ok, 1] // cell).astype(np.int64) * cw + (uv[ok, 0] // cell).astype(np.int64)
        zbuf = np.full(int(key.max()) + 1, np.inf)
        np.minimum.at(zbuf, key, Xc[ok, 2])
        tol = 0.004 + 0.01 * zbuf[key]  # a few mm: the surface's own thickness in a cell passes
        sel = np.flatnonzero(ok)
        ok[sel[Xc[ok, 2] > zbuf[key] + tol]] = False
        return ok

    def set_reference(self, gray: NDArray[np.generic], T_cw: Array, depth: NDArray[np.generic] | None = None,
                      mu_ref: Array | None = None) -> bool:
        """Take this image as the template. False when too little of it is visible. ``depth`` (metres, registered
        to the image): the static surroundings' template as well (see :attr:`DenseSettings.static_ring_px`).
        ``mu_ref``: the object's state in this image (measured elsewhere, e.g. from its depth:
        :mod:`.depth_state`); None: at rest. Each sample keeps its material point (rest position x_k) and takes
        its template intensity where the deformed object puts it, x_k + u_k(mu_ref)."""
        Xc = G.transform(T_cw @ self.T_mo, np.asarray(self.model.points, np.float64))
        z = float(np.median(Xc[:, 2][Xc[:, 2] > 0])) if np.any(Xc[:, 2] > 0) else 1.0
        smp = sample_surface(self.model, self.s.step_px * z / float(self.K[0, 0]), self.s.max_samples)
        x_ref = smp.x
        if mu_ref is not None:
            x_ref = smp.x + self.model.deformation_view(smp.nodes, self.n_modes, smp.weights).field.evaluate(
                np.asarray(mu_ref, np.float64))
        vis = self.visible(T_cw, G.transform(self.T_mo, x_ref), smp.normal @ self.T_mo[:3, :3].T)
        idx = np.flatnonzero(vis)
        self.levels, self.static = [], []
        self._taken.clear()
        if len(idx) < self.s.min_samples:
            return False
        uv = self.cam.project(G.transform(T_cw @ self.T_mo, x_ref[idx]), distort=False)
        pyr = pyramid(self.ideal(gray), self.s.levels)
        eye = G.transform(G.inv(T_cw @ self.T_mo), np.zeros((1, 3)))[0]  # the reference camera, object frame
        for lvl, img in enumerate(pyr):
            pick = np.arange(0, len(idx), 4**lvl)  # coarser levels: fewer samples, the same spread
            v = bilinear(img, _at_level(uv[pick], lvl)).astype(np.float64)
            good = np.isfinite(v)
            if not good.any():
                # no sample where the undistorted image has pixels (a lens whose undistortion sends this part of the
                # view outside the image, as a hostile CameraInfo's can): no template, as when out of view
                self.levels = []
                return False
            sel = idx[pick][good]
            normals = SmoothNormals.build(self.model, smp.face[sel], smp.weights[sel],
                                          np.broadcast_to(eye, (len(sel), 3)), self.n_modes)
            normals.set_reference(None if mu_ref is None else np.asarray(mu_ref, np.float64))
            self.levels.append(Level(smp.x[sel], smp.normal[sel],
                                     self.model.deformation_view(smp.nodes[sel], self.n_modes, smp.weights[sel]),
                                     v[good], normals))
        if depth is not None and self.s.rigid and self.s.static_ring_px > 0:
            self.static = self._surroundings(pyr, T_cw, uv, depth, int(self.s.static_share * len(idx)))
        self.template_views, self.template_closed, self._rest_motion = 1, False, float("inf")
        self._counts = [np.ones(len(L.values)) for L in self.levels]
        self._static_counts = [np.ones(len(S.values)) for S in self.static]
        self._mu_ref = None if mu_ref is None else np.asarray(mu_ref, np.float64).copy()
        self.rigid[:] = 0.0
        self.cam_corr[:] = 0.0
        self.rest_rigid[:] = 0.0
        self.rest_cam[:] = 0.0
        self.photo, self.rest_photo = self._photo0(), self._photo0()
        self.photo_s[:] = self.rest_photo_s[:] = (1.0, 0.0)
        self.held = None
        self.g_info[:], self.g_eta[:] = 0.0, 0.0
        self.g_frame = None
        return True

    def _footprint(self, uv: Array, shape: tuple[int, int], grow_px: float) -> NDArray[np.bool_]:
        """The pixels within ``grow_px`` of the object's samples at pixels ``uv`` (one level's resolution)."""
        mask = np.zeros(shape, np.uint8)
        q = np.round(uv[np.all(np.isfinite(uv), axis=1)]).astype(np.int64)
        q = q[(q[:, 0] >= 0) & (q[:, 1] >= 0) & (q[:, 0] < shape[1]) & (q[:, 1] < shape[0])]
        mask[q[:, 1], q[:, 0]] = 1
        r = max(1, int(np.ceil(grow_px)))
        out: NDArray[np.bool_] = cv2.dilate(mask, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1,) * 2)) > 0
        return out

    def _surroundings(self, pyr: list[NDArray[np.float32]], T_cw: Array, uv_obj: Array,
                      depth: NDArray[np.generic], count: int) -> list[StaticLevel]:
        """Template samples of what surrounds the object in the reference view: a ring ``static_ring_px`` wide
        around its outline (``static_margin_px`` off it, so that its edge and a load on it stay out), where the
        depth image is valid and smooth (no mixed pixels at a depth edge), back-projected to map-frame points.
        The camera's error moves them as it moves the object, and they cannot deform: they pin the rigid
        correction that a cantilever's bending would otherwise trade against."""
        h, w = pyr[0].shape
        D = self.ideal(depth, nearest=True)
        if D.shape != (h, w) or count < 10:
            return []
        D = np.where(np.isfinite(D) & (D > 0), D, np.nan).astype(np.float32)
        body = self._footprint(uv_obj, (h, w), self.s.step_px + 1)
        ring = self._footprint(uv_obj, (h, w), self.s.static_ring_px) & ~self._footprint(
            uv_obj, (h, w), self.s.step_px + 1 + self.s.static_margin_px)
        ring &= ~body
        filled = np.nan_to_num(D, nan=0.0)
        k3 = np.ones((3, 3), np.uint8)
        spread = cv2.dilate(filled, k3) - cv2.erode(np.where(filled > 0, filled, np.float32(1e9)), k3)
        ring &= np.isfinite(D) & (spread < 0.02 * np.nan_to_num(D, nan=1.0))
        step = max(1, round(self.s.step_px))
        ys, xs = np.mgrid[0:h:step, 0:w:step]
        pick = ring[ys, xs]
        u, v = xs[pick].astype(np.float64), ys[pick].astype(np.float64)
        if len(u) < 10:
            return []
        keep = np.unique(np.linspace(0, len(u) - 1, min(count, len(u))).astype(np.int64))
        u, v = u[keep], v[keep]
        z = D[v.astype(np.int64), u.astype(np.int64)].astype(np.float64)
        K = self.K
        Xc = np.c_[(u - K[0, 2]) * z / K[0, 0], (v - K[1, 2]) * z / K[1, 1], z]
        X = G.transform(G.inv(T_cw), Xc)
        uv = np.c_[u, v]
        out = []
        for lvl, img in enumerate(pyr):
            sub = np.arange(0, len(X), 4**lvl)
            vals = bilinear(img, _at_level(uv[sub], lvl)).astype(np.float64)
            good = np.isfinite(vals)
            out.append(StaticLevel(X[sub][good], vals[good]))
        return out

    def refine_template(self, gray: NDArray[np.generic], T_cw: Array, motion_px: float = 0.0) -> int:
        """Average this view into the template (:attr:`DenseSettings.template_frames`): the caller judged the object
        at rest here, in the reference state, before any deformation was seen. The zero-displacement fit (rigid
        correction, camera error and brightness; every level, from the last rest fit's values) aligns the template's
        samples with this image; each sample's intensity there, brought to the template's brightness ((I - b) / a),
        joins its running mean. A sample more than three robust standard deviations off the fit (an occluder, a
        highlight) is left out, as is every sample of a view whose gain is under a half. The static surroundings'
        template is averaged the same way with their own brightness. Returns the samples averaged at the finest
        level (0: none; a template taken in a deformed state, which the zero-displacement fit does not describe, is
        not refined). ``motion_px``: the image motion of this frame's deformed fit (:attr:`DenseResult.motion_px`);
        more than :attr:`DenseSettings.template_motion_px` beyond the least of the views averaged so far, a load too
        small to be judged a deformation is bending the object, and the averaging closes for good."""
        if self.s.template_frames <= self.template_views or not self.levels or self._mu_ref is not None \
                or self.template_closed:
            return 0
        if not motion_px <= self._rest_motion + self.s.template_motion_px:  # NaN closes it too
            self.template_closed = True
            return 0
        T_cw = np.asarray(T_cw, np.float64)
        pyr = pyramid(self.ideal(gray), len(self.levels))
        grads = _gradients(pyr)
        use_s = bool(self.static) and self.s.rigid
        zero = np.zeros(0)
        f = _Fit(None, np.zeros(0, bool), self.rest_rigid, self.rest_cam, self.rest_photo, self.rest_photo_s,
                 (np.zeros(N_RIGID), self._wide()), self.s.rigid and not (use_s and self.s.placement_measured), use_s)
        self._run(pyr, grads, f, T_cw, zero, zero, finest=0)
        if not f.photo[0] >= 0.5 or (use_s and not f.photo_s[0] >= 0.5):
            return 0
        done = 0
        for lvl, L in enumerate(self.levels):
            rows = self._visible_rows(L, None, f.total, T_cw)
            uv, _ = self._geometry(L, rows, None, f.total, T_cw, jac=False)
            v = bilinear(pyr[lvl], _at_level(uv, lvl)).astype(np.float64)
            n = self._average_in(L.values, self._counts[lvl], rows, v, self._predicted(L, rows, None, f.photo),
                                 f.photo[:2])
            done = n if lvl == 0 else done
            if use_s and n:
                S = self.static[lvl]
                srows = self._static_rows(lvl, f, T_cw, rows)
                uvs, _ = self._rigid_project(self._take(S.X, srows), f.cam, T_cw, jac=False)
                vs = bilinear(pyr[lvl], _at_level(uvs, lvl)).astype(np.float64)
                self._average_in(S.values, self._static_counts[lvl], srows, vs,
                                 f.photo_s[0] * self._take(S.values, srows) + f.photo_s[1], f.photo_s)
        self.template_views += 1
        self._rest_motion = min(self._rest_motion, float(motion_px))
        return done

    def _average_in(self, values: Array, counts: Array, rows: NDArray[np.int64], seen: Array, predicted: Array,
                    photo: Array) -> int:
        """Join the intensities ``seen`` at the template samples ``rows``, brought to the template's brightness
        ((I - b) / a, ``photo`` = (a, b)), to their running means in ``values`` (``counts`` views each so far), but
        those more than three robust standard deviations from ``predicted``; returns how many joined (0 where fewer
        than 10 were finite)."""
        r = seen - predicted
        ok = np.isfinite(r)
        if ok.sum() < 10:
            return 0
        ok[ok] = np.abs(r[ok]) <= 3.0 * self._scale(r[ok])
        sel = rows[ok]
        n = counts[sel]
        values[sel] += ((seen[ok] - photo[1]) / photo[0] - values[sel]) / (n + 1.0)
        counts[sel] = n + 1.0
        self._taken.clear()  # the gathers of the old values go
        return len(sel)

    def hold_rest(self) -> None:
        """The last frame showed no deformation: its zero-displacement fit's rho is the object's placement error
        as the images see it; deformed fits stay near it from now on (at it, where the surroundings measure the
        camera's error)."""
        self.held = self.rest_rigid.copy()

    # -- geometry -------------------------------------------------------------------------------------------
    def _rotation(self, omega: Array) -> Array:
        """exp(omega) for the rigid correction, remembered for the last few omegas (a solve asks for the same one
        many times)."""
        key = np.asarray(omega, np.float64).tobytes()
        R = self._rot_cache.get(key)
        if R is None:
            if len(self._rot_cache) >= 4:
                self._rot_cache.pop(next(iter(self._rot_cache)))
            R = self._rot_cache[key] = G.exp_so3(omega)
            R.flags.writeable = False  # shared by every caller of this omega
        return R

    def _take(self, a: Array, rows: NDArray[np.int64]) -> Array:
        """``a[rows]`` (read-only), kept for the few (array, rows) pairs in use: a level's fit gathers the same
        samples' positions and intensities at every iteration and every trial step. Keyed on the objects
        themselves (held here, so that neither is freed and its identity reused); neither is changed in place."""
        for src, idx, out in self._taken:
            if src is a and idx is rows:
                return out
        out = a[rows]
        out.flags.writeable = False
        self._taken.append((a, rows, out))
        if len(self._taken) > 6:
            self._taken.pop(0)
        return out

    def _to_camera(self, rigid: Array, T_cw: Array) -> tuple[Array, Array]:
        """(A, a): the camera-frame point A X + a of a map-frame point X moved by the rigid correction about the
        object's centre, c + R(omega) (X - c) + t, composed into one affine map."""
        A = T_cw[:3, :3] @ self._rotation(rigid[:3])
        a = A @ -self.c + T_cw[:3, :3] @ (self.c + rigid[3:]) + T_cw[:3, 3]
        return A, a

    def _pinhole(self, Xc: Array) -> Array:
        """Ideal pixels (N, 2) of camera-frame points; behind the camera: NaN."""
        z = Xc[:, 2]
        uv = np.empty((len(z), 2))
        with np.errstate(divide="ignore", invalid="ignore"):
            uv[:, 0] = self.K[0, 0] * Xc[:, 0] / z + self.K[0, 2]
            uv[:, 1] = self.K[1, 1] * Xc[:, 1] / z + self.K[1, 2]
        uv[z <= 0] = np.nan
        return uv

    def _rigid_project(self, X: Array, rigid: Array, T_cw: Array, jac: bool) -> tuple[Array, _Chain | None]:
        """Ideal pixels (N, 2) of map-frame points X moved by the rigid correction about the object's centre and,
        with ``jac``, what chains image gradients at them through the projection (:class:`_Chain`)."""
        if not jac:
            A, a = self._to_camera(rigid, T_cw)
            return self._pinhole(X @ A.T + a), None
        Rr = self._rotation(rigid[:3])
        d0 = (X - self.c) @ Rr.T
        Xc = (self.c + d0 + rigid[3:]) @ T_cw[:3, :3].T + T_cw[:3, 3]
        return self._pinhole(Xc), _Chain(Xc, d0, T_cw[:3, :3], Rr, self.K[0, 0], self.K[1, 1])

    def _geometry(self, L: Level, rows: NDArray[np.int64], mu: Array | None, rigid: Array, T_cw: Array,
                  jac: bool) -> tuple[Array, _Chain | None]:
        """Ideal pixels (N, 2) of the level's samples ``rows`` and, with ``jac``, what chains image gradients at
        them to d(intensity)/d(mu, omega, t) (:class:`_Chain`; ``mu`` None: zero displacement, no mu columns)."""
        x = self._take(L.x, rows)
        du: Array | None = None
        if mu is not None and jac:
            u_all, du_all = L.view.with_jacobian(mu)
            x = x + u_all[rows]
            du = du_all[rows]
        elif mu is not None:
            x = x + L.view.field.evaluate(mu)[rows]
        R_mo = self.T_mo[:3, :3]
        if not jac:  # object frame -> camera frame as one affine map
            A, a = self._to_camera(rigid, T_cw)
            return self._pinhole(x @ (A @ R_mo).T + (A @ self.T_mo[:3, 3] + a)), None
        uv, chain = self._rigid_project(x @ R_mo.T + self.T_mo[:3, 3], rigid, T_cw, jac=True)
        assert chain is not None
        chain.du, chain.R_mo = du, R_mo
        return uv, chain

    def _visible_rows(self, L: Level, mu: Array | None, rigid: Array, T_cw: Array) -> NDArray[np.int64]:
        x = L.x if mu is None else L.x + L.view.field.evaluate(mu)
        Rr = self._rotation(rigid[:3])
        X = (x @ self.T_mo[:3, :3].T + self.T_mo[:3, 3] - self.c) @ Rr.T + self.c + rigid[3:]
        return np.flatnonzero(self.visible(T_cw, X, L.normal @ (Rr @ self.T_mo[:3, :3]).T))

    def _static_rows(self, lvl: int, f: _Fit, T_cw: Array, obj_rows: NDArray[np.int64]) -> NDArray[np.int64]:
        """The surroundings' samples in view at level ``lvl``, less those the object (as fitted) may cover."""
        if not self.static or not f.cam_free:
            return np.zeros(0, np.int64)
        S, L = self.static[lvl], self.levels[lvl]
        uv, _ = self._rigid_project(S.X, f.cam, T_cw, jac=False)
        q = _at_level(uv, lvl)
        h, w = int(np.ceil(self.cam.height * 0.5**lvl)), int(np.ceil(self.cam.width * 0.5**lvl))
        ok = np.all(np.isfinite(q), axis=1) & (q[:, 0] >= 1) & (q[:, 1] >= 1) & (q[:, 0] <= w - 2) & (q[:, 1] <= h - 2)
        uv_o, _ = self._geometry(L, obj_rows, f.mu, f.total, T_cw, jac=False)
        cover = self._footprint(_at_level(uv_o, lvl), (h, w), self.s.step_px + 1 + self.s.static_margin_px * 0.5**lvl)
        qi = np.round(q[ok]).astype(np.int64)
        inside = cover[np.clip(qi[:, 1], 0, h - 1), np.clip(qi[:, 0], 0, w - 1)]
        sel: NDArray[np.int64] = np.flatnonzero(ok)[~inside]
        return sel

    # -- brightness -----------------------------------------------------------------------------------------
    def _brightness_basis(self, L: Level, rows: NDArray[np.int64], mu: Array | None) -> Array:
        """The columns the object's brightness parameters multiply (N, n_photo): I_ref, 1 and, with the
        shading, I_ref (n(mu) - n_ref); the predicted intensity is this times ``photo``."""
        ref = self._take(L.values, rows)
        cols = [ref, np.ones(len(rows))]
        if self.n_photo > 2:
            cols.append(ref[:, None] * L.normals.change(mu, rows))
        return np.column_stack(cols)

    def _predicted(self, L: Level, rows: NDArray[np.int64], mu: Array | None, photo: Array) -> Array:
        """a I_ref + b (+ I_ref (n(mu) - n_ref) . g): the shading as one number per triangle corner, blended."""
        ref = self._take(L.values, rows)
        out: Array = photo[0] * ref + photo[1]
        if self.n_photo > 2:
            dn = L.normals.corners(mu) - L.normals.corner_ref
            out = out + ref * L.normals.blend_rows(dn @ photo[2:], rows)
        return out

    def _g_prior(self) -> tuple[Array, Array]:
        """g's Gaussian prior (precision (3, 3), mean (3,)): about zero with 1-sigma ``prior_shading``, and with
        ``shading_frames`` what the earlier frames measured of g added to it (zero precision without the
        shading)."""
        if self.n_photo <= 2:
            return np.zeros((3, 3)), np.zeros(3)
        # asked several times an iteration, changed only when a frame's shading is accepted: kept (read-only)
        key = (self.s.prior_shading, self.g_info.tobytes(), self.g_eta.tobytes())
        if self._g_prior_memo is None or self._g_prior_memo[0] != key:
            P = np.eye(3) / self.s.prior_shading**2 + self.g_info
            m = np.asarray(np.linalg.solve(P, self.g_eta), np.float64)
            P.flags.writeable = m.flags.writeable = False
            self._g_prior_memo = (key, (P, m))
        return self._g_prior_memo[1]

    def _g_prior_cost(self, g: Array) -> float:
        """0.5 (g - m)^T P (g - m): g's prior in the units of the normalised residuals' cost (0 without the
        shading)."""
        if self.n_photo <= 2:
            return 0.0
        P, m = self._g_prior()
        d = np.asarray(g, np.float64) - m
        return 0.5 * float(d @ P @ d)

    def _g_column(self, f: _Fit) -> int:
        """The first of g's columns among a fit's unknowns (:meth:`_solve_level`'s order): after the free mu, the
        rigid parts' free ones and (a, b)."""
        return (0 if f.mu is None else int(np.sum(f.free))) + len(self._priors(f)[0]) + 2

    def _measure_shading(self, H: Array, g0: int, g: Array) -> None:
        """What this frame measured of g (:attr:`g_frame`, fused by :meth:`accept_shading`): g's block of the
        frame's normal matrix (``H``, its g columns from ``g0``, the prior included) with every other unknown
        marginalised out (a Schur complement: a frame whose g trades against its deformation measures little of
        it), less the prior, and that information times the data's own estimate, recovered from the posterior
        ``g`` (exact where Gauss-Newton converged; nothing is kept from a frame with a non-finite H or g)."""
        self.g_frame = None
        if self.s.shading_frames <= 0 or self.n_photo <= 2 or H.shape[0] < g0 + 3 or not np.all(np.isfinite(H)) \
                or not np.all(np.isfinite(g)):
            return
        idx = np.r_[g0:g0 + 3]
        rest = np.setdiff1d(np.arange(H.shape[0]), idx)
        C = H[np.ix_(idx, idx)]
        P, m = self._g_prior()
        try:
            if len(rest):
                B = H[np.ix_(rest, idx)]
                C = C - B.T @ (np.linalg.pinv(H[np.ix_(rest, rest)], hermitian=True) @ B)
            info = 0.5 * ((C - P) + (C - P).T)
            w, V = np.linalg.eigh(info)
        except np.linalg.LinAlgError:
            return
        info = (V * np.maximum(w, 0.0)) @ V.T  # the marginal's numerical noise: never negative information
        # the posterior (P + I) g = P m + I g_data, and P m is the fused sum itself
        self.g_frame = (info, (P + info) @ np.asarray(g, np.float64) - P @ m)

    def accept_shading(self) -> None:
        """Fuse the last solve's measurement of g into the next frames' prior (the caller judged that fit sound:
        a frame fitted with a load the model does not see yet, or a rejected one, would pin g where it is wrong);
        the earlier frames' information forgets 1/n per accepted frame."""
        if self.g_frame is None:
            return
        keep = 1.0 - 1.0 / max(self.s.shading_frames, 1)
        self.g_info = keep * self.g_info + self.g_frame[0]
        self.g_eta = keep * self.g_eta + self.g_frame[1]
        self.g_frame = None

    # -- the solve ------------------------------------------------------------------------------------------
    def _residuals(self, lvl: int, img: NDArray[np.float32], rows: NDArray[np.int64], f: _Fit,
                   T_cw: Array) -> Array:
        L = self.levels[lvl]
        uv, _ = self._geometry(L, rows, f.mu, f.total, T_cw, jac=False)
        r: Array = bilinear(img, _at_level(uv, lvl)).astype(np.float64) - self._predicted(L, rows, f.mu, f.photo)
        return r

    def _residuals_many(self, lvl: int, img: NDArray[np.float32], rows: NDArray[np.int64], f: _Fit, mus: Array,
                        T_cw: Array) -> Array:
        """:meth:`_residuals` with f's mu replaced by each row of ``mus`` (K, n_mu): (K, N), in one pass."""
        L = self.levels[lvl]
        ref = self._take(L.values, rows)
        pred = np.broadcast_to(f.photo[0] * ref + f.photo[1], (len(mus), len(rows)))
        dn = self._normals_change_many(L, mus)
        if dn is not None:
            pred = pred + ref * np.stack([L.normals.blend_rows(d @ f.photo[2:], rows) for d in dn])
        out: Array = self._sampled_many(lvl, img, rows, f, mus, T_cw) - pred
        return out

    def _static_residuals(self, lvl: int, img: NDArray[np.float32], rows: NDArray[np.int64], f: _Fit,
                          T_cw: Array) -> Array:
        S = self.static[lvl]
        uv, _ = self._rigid_project(self._take(S.X, rows), f.cam, T_cw, jac=False)
        r: Array = (bilinear(img, _at_level(uv, lvl)).astype(np.float64)
                    - (f.photo_s[0] * self._take(S.values, rows) + f.photo_s[1]))
        return r

    def _priors(self, f: _Fit) -> tuple[Array, Array]:
        """Diagonal weights and offsets of the rigid parts' Gaussian priors (rho where free, then epsilon where
        estimated), in the units of the normalised residuals."""
        wts, off = [], []
        if f.rho_free:
            mean, sd = f.prior
            wts.append(1.0 / sd**2)
            off.append(f.rigid - mean)
        if f.cam_free:
            sd = self._wide()
            wts.append(1.0 / sd**2)
            off.append(f.cam)
        if not wts:
            return np.zeros(0), np.zeros(0)
        return np.concatenate(wts), np.concatenate(off)

    def _wide(self) -> Array:
        """1-sigma of the rigid corrections' wide prior (omega, t) (read-only: asked several times an
        iteration)."""
        key = (self.s.prior_rot_rad, self.s.prior_trans_m)
        if self._wide_memo is None or self._wide_memo[0] != key:
            out: Array = np.repeat([self.s.prior_rot_rad, self.s.prior_trans_m], 3)
            out.flags.writeable = False
            self._wide_memo = (key, out)
        return self._wide_memo[1]

    @staticmethod
    def _rho(r: Array, c: float) -> float:
        """Tukey's biweight loss: a residual beyond ``c`` costs a constant. A redescending loss, not Huber's:
        an occluder's edge (the load itself) has image gradients fifty times the faint texture's, and under
        Huber every such sample would still pull with its full gradient."""
        q = np.minimum((r / c) ** 2, 1.0)
        return float(np.sum(c * c / 6.0 * (1.0 - (1.0 - q) ** 3)))

    @staticmethod
    def _weights(r: Array, c: float) -> Array:
        q = (r / c) ** 2
        w: Array = np.where(q < 1.0, (1.0 - q) ** 2, 0.0)
        return w

    @staticmethod
    def _scale(r: Array) -> float:
        """Robust standard deviation (1.4826 MAD), at least half an intensity level."""
        return max(1.4826 * _median(np.abs(r - _median(r))), 0.5)

    def _cost(self, lvl: int, img: NDArray[np.float32], rows: NDArray[np.int64], srows: NDArray[np.int64],
              f: _Fit, T_cw: Array, sig: tuple[float, float], counts: tuple[int, int]) -> float:
        """The normalised robust cost of a trial fit (each group's mean loss scaled to its count at the start of
        the iteration, so that a sample leaving the image does not look like an improvement) plus the priors."""
        r = self._residuals(lvl, img, rows, f, T_cw) / sig[0]
        ok = np.isfinite(r)
        c = self._rho(r[ok], TUKEY) * counts[0] / max(ok.sum(), 1)
        if len(srows):
            rs = self._static_residuals(lvl, img, srows, f, T_cw) / sig[1]
            oks = np.isfinite(rs)
            c += self._rho(rs[oks], TUKEY) * counts[1] / max(int(oks.sum()), 1)
        return float(c) + self._prior_cost(f)

    def _prior_cost(self, f: _Fit) -> float:
        """The rigid parts' and g's priors in the units of :meth:`_cost`."""
        pw, px = self._priors(f)
        return 0.5 * float(np.sum(pw * px * px)) + self._g_prior_cost(f.photo[2:])

    def _solve_level(self, lvl: int, pyr: list[NDArray[np.float32]], grads: list[Grad],
                     f: _Fit, T_cw: Array, lo: Array, hi: Array) -> tuple[Array, Array, float, NDArray[np.int64]]:
        """Levenberg-damped Gauss-Newton at one level; returns (J^T W J of the residuals normalised by their
        scale plus the priors' precisions, at the last linearisation; the object's final residuals, its scale
        sigma, its rows).

        Unknowns, in this order: the free mu, rho (where free), epsilon (where the surroundings are used), the
        object's brightness (a, b[, g]), the surroundings' brightness (where used)."""
        L = self.levels[lvl]
        rows = self._visible_rows(L, f.mu, f.total, T_cw)
        srows = self._static_rows(lvl, f, T_cw, rows)
        n_mu = 0 if f.mu is None else len(f.mu)
        free_mu = np.zeros(0, np.int64) if f.mu is None else np.flatnonzero(f.free)
        n_f = len(free_mu)
        use_s = len(srows) >= 10
        lam = 1e-3
        H = np.zeros((0, 0))
        r = np.zeros(0)
        sigma = 1.0
        for _ in range(self.s.iterations):
            uv, chain = self._geometry(L, rows, f.mu, f.total, T_cw, jac=True)
            assert chain is not None
            q = _at_level(uv, lvl)
            img, (gx, gy) = pyr[lvl], grads[lvl]
            # the shading's normals at this iteration's mu (their own change with mu is left out of the Jacobian:
            # the cost the steps are accepted on has it)
            B = self._brightness_basis(L, rows, f.mu)
            r = bilinear(img, q).astype(np.float64) - B @ f.photo
            ok = np.isfinite(r)
            if ok.sum() < self.s.min_samples // max(1, 4**lvl) or ok.sum() < 10:
                break
            rr = r[ok]
            sigma = self._scale(rr)
            g = np.stack([bilinear(gx, q[ok]), bilinear(gy, q[ok])], axis=1).astype(np.float64) * 0.5**lvl
            Jgeo = chain(g, ok)  # (N, n_mu + 6)
            Jr = Jgeo[:, n_mu:]
            cols = [Jgeo[:, free_mu]]
            if self.s.rigid and f.rho_free:
                cols.append(Jr)
            if self.s.rigid and f.cam_free:
                cols.append(Jr)
            cols.append(-B[ok])
            J = np.concatenate(cols, axis=1) / sigma
            res = rr / sigma
            sigma_s, n_s = 1.0, 0
            if use_s:
                S = self.static[lvl]
                uvs, chain_s = self._rigid_project(self._take(S.X, srows), f.cam, T_cw, jac=True)
                assert chain_s is not None
                qs = _at_level(uvs, lvl)
                rs = bilinear(img, qs).astype(np.float64) - (f.photo_s[0] * self._take(S.values, srows) + f.photo_s[1])
                oks = np.isfinite(rs)
                n_s = int(oks.sum())
                if n_s >= 10:
                    sigma_s = self._scale(rs[oks])
                    gs = np.stack([bilinear(gx, qs[oks]), bilinear(gy, qs[oks])], axis=1).astype(np.float64) * 0.5**lvl
                    Jsg = chain_s(gs, oks)
                    n_rho = 6 if f.rho_free else 0
                    Jstat = np.zeros((n_s, J.shape[1] + 2))
                    Jstat[:, n_f + n_rho:n_f + n_rho + 6] = Jsg
                    Jstat[:, -2] = -self._take(S.values, srows)[oks]
                    Jstat[:, -1] = -1.0
                    J = np.vstack([np.hstack([J, np.zeros((len(J), 2))]), Jstat / sigma_s])
                    res = np.concatenate([res, rs[oks] / sigma_s])
                else:
                    J = np.hstack([J, np.zeros((len(J), 2))])  # the surroundings' brightness: held by the damping
            w = self._weights(res, TUKEY)
            H = J.T @ (J * w[:, None])
            grad = J.T @ (w * res)
            pw, px = self._priors(f)
            if len(pw):
                H[n_f:n_f + len(pw), n_f:n_f + len(pw)] += np.diag(pw)
                grad[n_f:n_f + len(pw)] += pw * px
            if self.n_photo > 2:  # g's prior: its columns follow a and b
                gs0 = self._g_column(f)
                Pg, mg = self._g_prior()
                H[gs0:gs0 + 3, gs0:gs0 + 3] += Pg
                grad[gs0:gs0 + 3] += Pg @ (f.photo[2:] - mg)
            counts = (int(ok.sum()), n_s)
            sig = (sigma, sigma_s)
            s_fit = srows if n_s >= 10 else srows[:0]  # the surroundings' rows that entered this iteration
            # the cost at the start of the iteration from its own residuals (:meth:`_cost` at f)
            c0 = self._rho(res[:counts[0]], TUKEY) + (self._rho(res[counts[0]:], TUKEY) if len(s_fit) else 0.0) \
                + self._prior_cost(f)
            improved = False
            for _try in range(4):
                A = H + lam * np.diag(np.maximum(np.diag(H), 1e-9))
                try:
                    step = -np.asarray(np.linalg.solve(A, grad), np.float64)
                except np.linalg.LinAlgError:
                    lam *= 10
                    continue
                trial = self._apply(f, step, free_mu, lo, hi, use_s)
                c1 = self._cost(lvl, img, rows, s_fit, trial, T_cw, sig, counts)
                if c1 < c0:
                    f.mu, f.rigid, f.cam, f.photo, f.photo_s = trial.mu, trial.rigid, trial.cam, trial.photo, \
                        trial.photo_s
                    lam = max(lam / 3, 1e-7)
                    improved = c0 - c1 > self.s.tolerance * c0
                    break
                lam *= 4
            f.iterations += 1
            if not improved:  # converged (the cost moves by less than the tolerance) or no step helps
                break
        return H, r, sigma, rows

    def _fit_camera(self, pyr: list[NDArray[np.float32]], grads: list[Grad], f: _Fit, T_cw: Array) -> bool:
        """The camera pose's error epsilon (and the surroundings' brightness) from the static surroundings
        alone, coarse to fine, before the object's fit: what cannot deform measures the camera, and the object's
        fit then has no rigid motion of the whole view to trade against its bending. False (f untouched) when
        too few surroundings samples are in view."""
        wide = self._wide()
        cam, photo_s = f.cam.copy(), f.photo_s.copy()
        done = False
        for lvl in reversed(range(min(self.s.finest, len(self.levels) - 1), len(self.levels))):
            L, S = self.levels[lvl], self.static[lvl]
            rows = self._visible_rows(L, f.mu, f.total, T_cw)
            probe = _Fit(f.mu, f.free, f.rigid, cam, f.photo, photo_s, f.prior, False, True)
            srows = self._static_rows(lvl, probe, T_cw, rows)
            if len(srows) < max(10, self.s.min_samples // 4**lvl):
                continue
            img, (gx, gy) = pyr[lvl], grads[lvl]
            lam = 1e-3
            for _ in range(self.s.iterations):
                uv, chain = self._rigid_project(self._take(S.X, srows), cam, T_cw, jac=True)
                assert chain is not None
                q = _at_level(uv, lvl)
                r = bilinear(img, q).astype(np.float64) - (photo_s[0] * self._take(S.values, srows) + photo_s[1])
                ok = np.isfinite(r)
                if ok.sum() < 10:
                    break
                sig = self._scale(r[ok])
                g = np.stack([bilinear(gx, q[ok]), bilinear(gy, q[ok])], axis=1).astype(np.float64) * 0.5**lvl
                J = np.concatenate([chain(g, ok), np.stack([-self._take(S.values, srows)[ok], -np.ones(ok.sum())],
                                                           axis=1)], axis=1) / sig
                res = r[ok] / sig
                w = self._weights(res, TUKEY)
                pw = np.r_[1.0 / wide**2, 0.0, 0.0]
                H = J.T @ (J * w[:, None]) + np.diag(pw)
                grad = J.T @ (w * res) + pw * np.r_[cam, 0.0, 0.0]

                n_ok = int(ok.sum())
                c0 = self._camera_cost(lvl, img, S, srows, cam, photo_s, T_cw, sig, n_ok)
                improved = False
                for _try in range(4):
                    try:
                        step = -np.linalg.solve(H + lam * np.diag(np.maximum(np.diag(H), 1e-9)), grad)
                    except np.linalg.LinAlgError:
                        lam *= 10
                        continue
                    c_t = np.clip(cam + step[:6], -3 * wide, 3 * wide)
                    p_t = photo_s + step[6:]
                    c1 = self._camera_cost(lvl, img, S, srows, c_t, p_t, T_cw, sig, n_ok)
                    if c1 < c0:
                        cam, photo_s = c_t, p_t
                        lam = max(lam / 3, 1e-7)
                        improved = c0 - c1 > self.s.tolerance * c0
                        break
                    lam *= 4
                if not improved:
                    break
            done = True
        if done:
            f.cam, f.photo_s = cam, photo_s
        return done

    def _camera_cost(self, lvl: int, img: NDArray[np.float32], S: StaticLevel, srows: NDArray[np.int64], cam: Array,
                     photo_s: Array, T_cw: Array, sig: float, count: int) -> float:
        """The surroundings' robust cost (mean loss scaled to ``count``, as :meth:`_cost`) plus epsilon's prior."""
        uv, _ = self._rigid_project(self._take(S.X, srows), cam, T_cw, jac=False)
        r = (bilinear(img, _at_level(uv, lvl)).astype(np.float64)
             - (photo_s[0] * self._take(S.values, srows) + photo_s[1]))
        ok = np.isfinite(r)
        wide = self._wide()
        return (self._rho(r[ok] / sig, TUKEY) * count / max(int(ok.sum()), 1)
                + 0.5 * float(np.sum(cam * cam / wide**2)))

    def _apply(self, f: _Fit, step: Array, free_mu: NDArray[np.int64], lo: Array, hi: Array,
               use_s: bool) -> _Fit:
        out = f.copy()
        n_f = len(free_mu)
        if out.mu is not None and n_f:
            out.mu[free_mu] = np.clip(out.mu[free_mu] + step[:n_f], lo[free_mu], hi[free_mu])
        k = n_f
        if self.s.rigid and f.rho_free:
            mean, sd = f.prior
            out.rigid = np.clip(out.rigid + step[k:k + 6], mean - 3 * sd, mean + 3 * sd)
            k += 6
        if self.s.rigid and f.cam_free:
            wide = self._wide()
            out.cam = np.clip(out.cam + step[k:k + 6], -3 * wide, 3 * wide)
            k += 6
        out.photo = out.photo + step[k:k + self.n_photo]
        if use_s:
            out.photo_s = out.photo_s + step[k + self.n_photo:k + self.n_photo + 2]
        return out

    def _profile_cost(self, lvl: int, img: NDArray[np.float32], rows: NDArray[np.int64], f: _Fit, mu: Array,
                      T_cw: Array, sigma: float) -> float:
        """The level's robust cost of the object's samples at ``mu`` with the brightness (a, b and the shading g)
        at its best for that mu (Tukey-weighted least squares with g's prior, two passes) and the rigid parts as
        fitted: the profile of the cost over mu."""
        return self._profile(lvl, img, rows, f, mu, T_cw, sigma)[0]

    def _profile(self, lvl: int, img: NDArray[np.float32], rows: NDArray[np.int64], f: _Fit, mu: Array,
                 T_cw: Array, sigma: float, cold: bool = False) -> tuple[float, Array, int]:
        """:meth:`_profile_cost`, the brightness that attains it and how many samples fell inside the image (the
        cost is a mean over them). ``cold``: the reweighting starts from the
        plain least-squares brightness at this mu, its first pass at that fit's own residual scale (at least
        ``sigma``), instead of from the fit's brightness (which a misaligned frame may have left at a gain near
        zero and a bias far off: every sample would then lie beyond Tukey's threshold)."""
        L = self.levels[lvl]
        uv, _ = self._geometry(L, rows, mu, f.total, T_cw, jac=False)
        v = bilinear(img, _at_level(uv, lvl)).astype(np.float64)
        ok = np.isfinite(v)
        n = int(ok.sum())
        if n < 10:
            return float("inf"), f.photo.copy(), n
        cost, p = self._best_brightness(v[ok], self._brightness_basis(L, rows[ok], mu), f, sigma, cold)
        return cost, p, n

    def _profile_many(self, lvl: int, img: NDArray[np.float32], rows: NDArray[np.int64], f: _Fit, mus: Array,
                      T_cw: Array, sigma: float) -> list[float]:
        """:meth:`_profile_cost` at each row of ``mus`` (K, n_mu): the samples of every candidate placed and read
        in one pass, the brightness fitted to each."""
        L = self.levels[lvl]
        v = self._sampled_many(lvl, img, rows, f, mus, T_cw)
        dn = self._normals_change_many(L, mus)
        out = []
        for k in range(len(mus)):
            ok = np.isfinite(v[k])
            if ok.sum() < 10:
                out.append(float("inf"))
                continue
            ref = L.values[rows[ok]]
            cols = [ref, np.ones(len(ref))]
            if dn is not None:
                cols.append(ref[:, None] * L.normals.blend_rows(dn[k], rows[ok]))
            out.append(self._best_brightness(v[k][ok], np.column_stack(cols), f, sigma, False)[0])
        return out

    def _sampled_many(self, lvl: int, img: NDArray[np.float32], rows: NDArray[np.int64], f: _Fit, mus: Array,
                      T_cw: Array) -> Array:
        """The image at the level's samples ``rows`` deformed by each row of ``mus`` (K, N; NaN outside): as
        :meth:`_geometry` without the Jacobian, every candidate in one product and one lookup."""
        L = self.levels[lvl]
        x = self._take(L.x, rows)[None] + L.view.field.evaluate_many(mus)[:, rows]  # (K, N, 3)
        A, a = self._to_camera(f.total, T_cw)
        R_mo = self.T_mo[:3, :3]
        uv = self._pinhole(x.reshape(-1, 3) @ (A @ R_mo).T + (A @ self.T_mo[:3, 3] + a))
        out: Array = bilinear(img, _at_level(uv, lvl)).astype(np.float64).reshape(len(mus), len(rows))
        return out

    def _normals_change_many(self, L: Level, mus: Array) -> Array | None:
        """n(mu) - n_ref at the samples' triangles' corners for each row of ``mus`` (K, 3 F, 3); None without the
        shading."""
        if self.n_photo <= 2:
            return None
        out: Array = L.normals.corners_many(mus) - L.normals.corner_ref
        return out

    def _best_brightness(self, v: Array, B: Array, f: _Fit, sigma: float, cold: bool) -> tuple[float, Array]:
        """The profile's inner fit (:meth:`_profile`): the brightness at its best for the intensities ``v`` of the
        samples in view and their basis ``B``, and the mean robust cost there."""
        prior = np.zeros((self.n_photo, self.n_photo))
        pull = np.zeros(self.n_photo)
        g_mean = np.zeros(self.n_photo - 2)
        if self.n_photo > 2:  # g's prior in intensity units, as the residuals below
            Pg, g_mean = self._g_prior()
            prior[2:, 2:] = Pg * sigma**2
            pull[2:] = prior[2:, 2:] @ g_mean
        p = f.photo.copy()
        scales = [sigma, sigma]
        if cold:
            try:
                p = np.asarray(np.linalg.solve(B.T @ B + prior, B.T @ v + pull), np.float64)
            except np.linalg.LinAlgError:
                return float("inf"), f.photo.copy()
            scales = [max(sigma, self._scale(v - B @ p)), sigma, sigma]
        for sc in scales:
            w = self._weights((v - B @ p) / sc, TUKEY)
            if float(w.sum()) <= 0:
                return float("inf"), f.photo.copy()
            A = B.T @ (B * w[:, None]) + prior
            try:
                p = np.asarray(np.linalg.solve(A, B.T @ (w * v) + pull), np.float64)
            except np.linalg.LinAlgError:
                p = np.r_[1.0, float(w @ v) / float(w.sum()), g_mean]
        cost = self._rho((v - B @ p) / sigma, TUKEY) + self._g_prior_cost(p[2:])
        return cost / len(v), p

    def _refine(self, lvl: int, img: NDArray[np.float32], rows: NDArray[np.int64], f: _Fit, T_cw: Array,
                lo: Array, hi: Array, sigma: float) -> Array:
        """A derivative-free search of the profile cost over each free mu about the Gauss-Newton solution, at
        the finest level fitted. On a faint texture the image gradients that Gauss-Newton linearises with are
        mostly noise (its steps come out short, and the brightness gain trades against the misalignment), and
        the coarse levels it starts from are biased (a pyramid level sees the texture at another scale than the
        reference did); the profile cost itself has its minimum where the samples line up."""
        assert f.mu is not None
        mu = f.mu.copy()
        free = np.flatnonzero(f.free)
        if len(free) == 0 or len(free) > 3:
            return mu
        best = self._profile_cost(lvl, img, rows, f, mu, T_cw, sigma)
        for _sweep in range(1 if len(free) == 1 else 2):
            for i in free:
                width = self.s.refine_span * (hi[i] - lo[i])
                for _round in range(3):  # a grid of 7 about the best so far, narrowed by 3 each round
                    grid = np.clip(mu[i] + np.linspace(-width, width, 7), lo[i], hi[i])
                    trials = np.repeat(mu[None], len(grid), axis=0)
                    trials[:, i] = grid
                    trials = trials[grid != mu[i]]
                    # a candidate's cost depends on f, not on the best so far: costed together, then kept as the
                    # running minimum in order, they pick what the one-by-one loop picked
                    costs = self._profile_many(lvl, img, rows, f, trials, T_cw, sigma) if len(trials) else []
                    for trial, c in zip(trials, costs):
                        if c < best:
                            best, mu = c, trial.copy()
                    width /= 3.0
        return mu

    def _grid_start(self, pyr: list[NDArray[np.float32]], f: _Fit, T_cw: Array, lo: Array, hi: Array) -> None:
        """Coarse search over the free parameters at the coarsest level (the warm start included): a load that
        jumped lands in another basin of the photometric cost."""
        if f.mu is None or not self.s.grid or not f.free.any():
            return
        lvl = len(self.levels) - 1
        L = self.levels[lvl]
        rows = self._visible_rows(L, f.mu, f.total, T_cw)
        free = np.flatnonzero(f.free)
        per = max(2, round(self.s.grid ** (1.0 / len(free))))
        axes = [np.linspace(lo[i], hi[i], per) for i in free]
        cands = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(free))
        r0 = self._residuals(lvl, pyr[lvl], rows, f, T_cw)
        ok0 = np.isfinite(r0)
        if ok0.sum() < 10:
            return
        sigma = self._scale(r0[ok0])
        fitted = self.s.grid_brightness == "always" or (
            self.s.grid_brightness == "auto" and not float(f.photo[0]) >= self.s.min_gain)
        if fitted:
            best_c, best_p, _ = self._profile(lvl, pyr[lvl], rows, f, f.mu, T_cw, sigma, cold=True)
        else:
            best_c, best_p = self._rho(r0[ok0], TUKEY * sigma) / ok0.sum(), f.photo
        best = None
        seen: list[tuple[Array, float]] = []  # the valid candidates and their costs
        mus = np.repeat(f.mu[None], len(cands), axis=0)
        mus[:, free] = cands
        resid = None if fitted else np.concatenate([  # in chunks: a fine grid must not hold every candidate's samples
            self._residuals_many(lvl, pyr[lvl], rows, f, mus[k:k + _CANDIDATES], T_cw)
            for k in range(0, len(mus), _CANDIDATES)])
        for k, cnd in enumerate(cands):
            t = f.copy()
            assert t.mu is not None
            t.mu[free] = cnd
            if resid is None:  # one sampling per candidate: the profile counts the samples in view
                c, p, n = self._profile(lvl, pyr[lvl], rows, t, t.mu, T_cw, sigma, cold=True)
            else:
                r = resid[k]
                ok = np.isfinite(r)
                n = int(ok.sum())
                c, p = (self._rho(r[ok], TUKEY * sigma) / n if n else float("inf")), f.photo
            if n < 0.8 * ok0.sum():
                continue
            seen.append((cnd, c))
            if c < best_c:
                best, best_c, best_p = t.mu, c, p
        if best is not None:
            f.mu = best
        # the runner-up from another basin: the cheapest grid candidate more than a quarter of a range from the
        # winner (the warm start is not one of them), its cost above the winner's as a share of it (small: two places
        # explain the image about as well). A diagnostic: its scale differs where the brightness was fitted (the
        # profile, with g's prior) and where it was not
        win, span = f.mu[free], np.maximum(hi[free] - lo[free], 1e-12)
        far = [(c, cnd) for cnd, c in seen if np.max(np.abs(cnd - win) / span) > 0.25]
        if far and np.isfinite(best_c) and best_c > 0:
            c_far, cnd_far = min(far, key=lambda x: x[0])
            self.grid_margin = float((c_far - best_c) / best_c)
            self.grid_runner_up = f.mu.copy()
            self.grid_runner_up[free] = cnd_far
        if np.isfinite(best_c) and np.all(np.isfinite(best_p)):  # never a non-finite brightness into the solve
            f.photo = np.asarray(best_p, np.float64).copy()

    def _fit_from(self, pyr: list[NDArray[np.float32]], grads: list[Grad], f: _Fit, T_cw: Array, lo: Array,
                  hi: Array, finest: int) -> list[tuple[Array, Array, float, NDArray[np.int64]]]:
        """Gauss-Newton coarse to fine from ``f`` (in place), then the search of the cost at the finest level
        (:attr:`DenseSettings.refine`); per level as :meth:`_run`."""
        per_level = self._run(pyr, grads, f, T_cw, lo, hi, finest=finest)
        _, _, sigma, rows = per_level[-1]
        if f.mu is not None and self.s.refine and len(rows) >= self.s.min_samples and np.isfinite(sigma):
            f.mu = self._refine(finest, pyr[finest], rows, f, T_cw, lo, hi, sigma)
        return per_level

    def _run(self, pyr: list[NDArray[np.float32]], grads: list[Grad], f: _Fit,
             T_cw: Array, lo: Array, hi: Array, finest: int = 0) -> list[tuple[Array, Array, float, NDArray[np.int64]]]:
        """Coarse to fine down to level ``finest``: per level (J^T W J, residuals, sigma, rows), coarsest first."""
        return [self._solve_level(lvl, pyr, grads, f, T_cw, lo, hi)
                for lvl in reversed(range(finest, len(self.levels)))]

    def solve(self, gray: NDArray[np.generic], T_cw: Array, mu0: Array, lo: Array, hi: Array,
              with_rest: bool = True) -> DenseResult:
        """Fit mu (within [lo, hi]; a parameter with lo == hi stays put) and the nuisances to this image."""
        T_cw = np.asarray(T_cw, np.float64)
        self.g_frame = None
        self.grid_margin = float("nan")
        self.grid_runner_up = None
        pyr = pyramid(self.ideal(gray), len(self.levels))
        grads = _gradients(pyr)
        free = hi > lo
        wide = self._wide()
        held = np.repeat([self.s.held_rot_rad, self.s.held_trans_m], 3)
        use_s = bool(self.static) and self.s.rigid
        prior = (np.zeros(N_RIGID), wide) if self.held is None else (self.held, held)
        # where the surroundings measure the camera's error, the object's own placement error is not fitted again
        # when the registration measured it from the same depth (a free rho trades against a cantilever's
        # bending: development seed 46 went from 0.2 % to 24 %), and held where rest put it otherwise
        rho_free = self.s.rigid and not (use_s and (self.s.placement_measured or self.held is not None))
        rho0 = self.held if (self.held is not None and not rho_free) else self.rigid
        f = _Fit(np.clip(mu0, lo, hi), free, rho0, self.cam_corr, self.photo, self.photo_s, prior, rho_free, use_s)
        cam_first = use_s and self.s.camera_first and self._fit_camera(pyr, grads, f, T_cw)
        if cam_first:
            f.cam_free = False  # measured on the surroundings alone: held in the object's fit
        start = f.copy()
        self._grid_start(pyr, f, T_cw, lo, hi)
        finest = min(self.s.finest, len(self.levels) - 1)
        per_level = self._fit_from(pyr, grads, f, T_cw, lo, hi, finest)
        H, r, sigma, rows = per_level[-1]
        assert f.mu is not None
        basin_gap, switched, other, warm_ran, other_apart = float("nan"), 0.0, None, 0.0, 0.0
        alt_mu = self.grid_runner_up
        if (alt_mu is not None and self.grid_margin < self.s.basin_check and len(rows) >= self.s.min_samples
                and np.isfinite(sigma)):
            # the runner-up from another basin, fitted as the winner was; the cheapest at the finest level is kept
            alt = start.copy()
            alt.mu = alt_mu.copy()
            ends = [(f, per_level), (alt, self._fit_from(pyr, grads, alt, T_cw, lo, hi, finest))]
            span = np.maximum(np.asarray(hi, float) - np.asarray(lo, float), 1e-12)
            fi_b = np.flatnonzero(free)

            def apart(a: Array, b: Array) -> float:
                return float(np.max(np.abs(a - b)[fi_b] / span[fi_b]))

            # the warm start (the last frame's estimate) where both fits ended more than a quarter of a range from
            # it: the coarse search's winner and runner-up can share one wrong basin while the last frame's is right
            assert start.mu is not None and alt.mu is not None
            if self.s.basin_warm and apart(start.mu, f.mu) > 0.25 and apart(start.mu, alt.mu) > 0.25:
                warm = start.copy()
                ends.append((warm, self._fit_from(pyr, grads, warm, T_cw, lo, hi, finest)))
                warm_ran = 1.0
            costs = [self._profile_cost(finest, pyr[finest], pl[-1][3], e, e.mu, T_cw, sigma)
                     if len(pl[-1][3]) >= self.s.min_samples and np.isfinite(pl[-1][2]) else float("inf")
                     for e, pl in ends]
            k = int(np.argmin(costs))
            if np.isfinite(costs[k]) and k > 0:
                f, per_level, switched = ends[k][0], ends[k][1], float(k)
                H, r, sigma, rows = per_level[-1]
            rest = [i for i in range(len(ends)) if i != k and np.isfinite(costs[i])]
            # the other basin: the cheapest of the other fits that ended apart from the kept one, else the cheapest
            far = [i for i in rest if apart(ends[i][0].mu, f.mu) > self.s.ambiguity_apart]
            if rest:
                j = min(far or rest, key=lambda i: costs[i])
                other = ends[j][0].mu
                other_apart = apart(other, f.mu) if len(fi_b) else 0.0
                if costs[k] > 0:
                    basin_gap = float((costs[j] - costs[k]) / costs[k])
        assert f.mu is not None
        n_mu = len(mu0)
        res = DenseResult(f.mu.copy(), np.full((n_mu, n_mu), np.nan), sigma, float("nan"), len(rows),
                          int(np.sum(np.abs(r[np.isfinite(r)]) <= TUKEY * sigma)), 0.0, f.iterations)
        if len(rows) < self.s.min_samples or not np.isfinite(sigma):
            res.reason = f"only {len(rows)} object samples visible (need {self.s.min_samples})"
            return res
        self.rigid, self.cam_corr, self.photo, self.photo_s = f.rigid.copy(), f.cam.copy(), f.photo.copy(), \
            f.photo_s.copy()
        self._measure_shading(H, self._g_column(f), f.photo[2:])
        cam_gap = float("nan")
        if use_s and not cam_first and self.s.camera_check:
            # the surroundings alone, from the joint fit's camera: where they want the camera elsewhere, the joint
            # fit has traded the camera's error against the object's deformation
            probe = f.copy()
            # coarse to fine (from the finest level alone it missed a 10 mm disagreement: tests/assimilation)
            if self._fit_camera(pyr, grads, probe, T_cw):
                cam_gap = float(np.linalg.norm((probe.cam - f.cam) / wide))
        fi = np.flatnonzero(free)
        if len(fi) and H.shape[0] >= len(fi):
            with contextlib.suppress(np.linalg.LinAlgError):
                res.cov_mu[np.ix_(fi, fi)] = np.linalg.inv(H)[: len(fi), : len(fi)]
        L = self.levels[min(self.s.finest, len(self.levels) - 1)]
        uv_d, _ = self._geometry(L, rows, f.mu, f.total, T_cw, jac=False)
        uv_0, _ = self._geometry(L, rows, None, f.total, T_cw, jac=False)
        mv = np.linalg.norm(uv_d - uv_0, axis=1)
        res.motion_px = float(np.percentile(mv[np.isfinite(mv)], 90)) if np.isfinite(mv).any() else 0.0
        res.debug.update(rigid_rot_deg=float(np.rad2deg(np.linalg.norm(f.rigid[:3]))),
                         rigid_trans_mm=float(1e3 * np.linalg.norm(f.rigid[3:])), gain=float(f.photo[0]),
                         bias=float(f.photo[1]), shading=float(np.linalg.norm(f.photo[2:])),
                         static_samples=float(len(self.static[0].X) if use_s else 0),
                         camera_rot_deg=float(np.rad2deg(np.linalg.norm(f.cam[:3]))),
                         camera_trans_mm=float(1e3 * np.linalg.norm(f.cam[3:])),
                         camera_gap_sigma=cam_gap, grid_margin=self.grid_margin, basin_gap=basin_gap,
                         basin_switched=switched, basin_warm=warm_ran)
        if other is not None:  # where the other basin's fit ended (benchmarks/family.py records it) and how far apart
            res.debug.update({f"basin_other_{i}": float(other[i]) for i in fi})
            res.debug["basin_apart"] = other_apart
        if with_rest:
            # is there a deformation at all? The same fit with zero displacement, at the coarser levels only (it
            # is a yes/no question), compared with the deformed fit's residual at the same level
            cmp = min(max(1, self.s.finest), len(self.levels) - 1)
            g0 = _Fit(None, free, self.rest_rigid, f.cam if cam_first else self.rest_cam, self.rest_photo,
                      self.rest_photo_s, (np.zeros(N_RIGID), wide),
                      self.s.rigid and not (use_s and self.s.placement_measured), use_s and not cam_first)
            sigma0 = self._run(pyr, grads, g0, T_cw, lo, hi, finest=cmp)[-1][2]
            self.rest_rigid, self.rest_cam = g0.rigid.copy(), g0.cam.copy()
            self.rest_photo, self.rest_photo_s = g0.photo.copy(), g0.photo_s.copy()
            res.rest_rms = sigma0
            res.debug["rms_at_rest_level"] = per_level[len(per_level) - 1 - cmp][2]
        return res
