"""Which lens-distortion terms a wand dance determines, camera by camera.

A wand that sweeps only the middle of an image says little about how the lens bends rays
at the image's edge; fitting ``k2``, ``k3`` or the tangential terms from it gives
polynomials that fit the middle and turn wild (or fold) towards the edges, where a later
trial's markers may well go. The candidates are tried in a fixed order,
``k1``, ``k2``, ``(p1, p2)``, ``k3`` (:data:`CANDIDATES`; ``k2`` needs ``k1``, ``k3``
needs ``k2``), each together with those already kept. A candidate is kept when

* the wand covered enough of the camera's image (:data:`MIN_COVERAGE`, fraction of a
  16 x 12 grid of cells), and
* the data determine it: its Gauss-Newton estimate from the current rig is at least
  :data:`MIN_T` standard errors from zero (for the pair, either term).

Estimates and standard errors come from the normal equations: the reduced camera system
of the bundle adjustment (wand poses eliminated), restricted to the adjusted parameters
(poses, principal distances and points of every camera, the candidate terms of this
one) and scaled to unit diagonal, is inverted; the covariance is in units of the
image-point variance, scaled by the robust residual variance. The covariance is also
propagated to the distortion displacement at points on a grid over the whole image
(``spotlab.geometry.lens_check.image_grid``): ``edge_sd``, how well the kept terms pin
the lens down at the image's edges, in units of the image noise.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from spotlab.calibration._camera_block import BLOCK, INTRINSIC_NAMES
from spotlab.calibration._wand_bundle import (
    BundleProblem,
    BundleState,
    adjust,
    reduced_camera_system,
    residuals,
    robust_sigma,
)
from spotlab.core.errors import CalibrationError
from spotlab.geometry.lens_check import image_grid

__all__ = [
    "ALL_TERMS",
    "LADDER",
    "MIN_COVERAGE",
    "PRESETS",
    "LensChoice",
    "choose_terms",
    "edge_sd",
    "fit_fixed_terms",
    "lens_mode",
    "next_step",
    "term_columns",
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

ALL_TERMS = ("k1", "k2", "p1", "p2", "k3")
#: Candidates in the order tried, each with the term it needs kept first.
CANDIDATES: tuple[tuple[tuple[str, ...], str], ...] = (
    (("k1",), ""),
    (("k2",), "k1"),
    (("p1", "p2"), ""),
    (("k3",), "k2"),
)
#: Steps of increasing flexibility, each a superset of the one before: a camera whose
#: fitted model does not invert over its image falls to the step below.
LADDER: tuple[tuple[str, ...], ...] = (
    (),
    ("k1",),
    ("k1", "k2"),
    ("k1", "k2", "p1", "p2"),
    ALL_TERMS,
)
#: Named term sets of ``spotlab calibrate --distortion``.
PRESETS: dict[str, tuple[str, ...]] = {"none": (), "radial": ("k1", "k2"), "full": ALL_TERMS}
#: Smallest fraction of the image the wand must cover before a term is fitted.
MIN_COVERAGE = {"k1": 0.03, "k2": 0.1, "p1": 0.15, "p2": 0.15, "k3": 0.3}
#: Smallest estimate, in standard errors, of a term that is fitted.
MIN_T = 3.0


@dataclass(frozen=True)
class LensChoice:
    """The terms chosen for one camera and why.

    Attributes
    ----------
    terms : tuple of str
        Terms fitted, in :data:`ALL_TERMS` order.
    edge_sd : float
        Largest SD of the modelled distortion over the image, in units of the
        image-point noise (0 for no terms; inf where the terms are not determined; NaN
        for a set taken after the lens check, not estimated).
    reason : str
        One sentence: why these and not more.
    limited_by : str
        ``"coverage"``, ``"conditioning"``, ``"inversion"``, ``"chosen"`` (a fixed set
        was asked for) or ``""`` (nothing more to fit).
    """

    terms: tuple[str, ...]
    edge_sd: float
    reason: str
    limited_by: str


def term_columns(terms: Sequence[str]) -> list[int]:
    """Block columns (0..14) of distortion terms."""
    return [6 + INTRINSIC_NAMES.index(t) for t in terms]


def _distortion_jacobian(
    block: FloatArray, size: tuple[int, int], terms: Sequence[str]
) -> FloatArray:
    """d(u, v)/d(terms) at points over the whole image, shape (n, 2, len(terms)) (px)."""
    fx, fy, cx, cy = block[6:10]
    uv = image_grid(size, 9)
    x, y = (uv[:, 0] - cx) / fx, (uv[:, 1] - cy) / fy
    r2 = x * x + y * y
    r4 = r2 * r2
    columns = {
        "k1": (x * r2, y * r2),
        "k2": (x * r4, y * r4),
        "p1": (2.0 * x * y, r2 + 2.0 * y * y),
        "p2": (r2 + 2.0 * x * x, 2.0 * x * y),
        "k3": (x * r4 * r2, y * r4 * r2),
    }
    jac = np.empty((uv.shape[0], 2, len(terms)))
    for j, t in enumerate(terms):
        jac[:, 0, j] = fx * columns[t][0]
        jac[:, 1, j] = fy * columns[t][1]
    return jac


def _solve(
    S: FloatArray, g: FloatArray, free: BoolArray, terms: Sequence[Sequence[str]]
) -> tuple[list[FloatArray], list[FloatArray]]:
    """Gauss-Newton step and covariance (unit noise) of every camera's ``terms``, jointly.

    Returns per camera (step (k,), covariance (k, k)); inf covariances when the system
    is singular.
    """
    mask = free.copy()
    mask[:, 10:15] = False
    for c, t in enumerate(terms):
        mask[c, term_columns(t)] = True
    index = np.flatnonzero(mask.ravel())
    A = S[np.ix_(index, index)]
    d = np.sqrt(np.clip(np.diag(A), 1e-300, None))
    w, v = np.linalg.eigh(A / d[:, None] / d[None, :])
    if not w[0] > 1e-12 * w[-1]:
        return (
            [np.zeros(len(t)) for t in terms],
            [np.full((len(t), len(t)), np.inf) for t in terms],
        )
    full_step = -(v / w) @ (v.T @ (g[index] / d)) / d
    steps, covs = [], []
    for c, t in enumerate(terms):
        pos = [int(np.searchsorted(index, c * BLOCK + col)) for col in term_columns(t)]
        sub = v[pos] / d[pos, None]
        covs.append((sub / w) @ sub.T)
        steps.append(full_step[pos])
    return steps, covs


def edge_sd(
    S: FloatArray,
    free: BoolArray,
    blocks: FloatArray,
    sizes: Sequence[tuple[int, int]],
    terms: Sequence[Sequence[str]],
) -> list[float]:
    """Largest SD of each camera's modelled distortion over its image.

    Parameters
    ----------
    S : ndarray, shape (15 C, 15 C)
        Reduced camera system (``_wand_bundle.reduced_camera_system``).
    free : ndarray of bool, shape (C, 15)
        Parameters adjusted besides the distortion terms (pose, principal distances,
        principal point); the other cameras' distortion stays fixed.
    blocks : ndarray, shape (C, 15)
        Current camera blocks (principal distances and point, px).
    sizes : sequence of (int, int)
        Image sizes (px).
    terms : sequence of sequence of str
        Distortion terms fitted, per camera (estimated jointly).

    Returns
    -------
    list of float
        Per camera, max over grid points and both coordinates of the displacement SD,
        in units of the image-point noise SD; 0 for no terms, inf when not determined.
    """
    _, covs = _solve(S, np.zeros(S.shape[0]), free, terms)
    out = []
    for c, (t, cov) in enumerate(zip(terms, covs, strict=True)):
        if not t:
            out.append(0.0)
        elif not np.all(np.isfinite(cov)):
            out.append(float("inf"))
        else:
            jac = _distortion_jacobian(blocks[c], sizes[c], t)
            out.append(float(np.sqrt(np.max(np.einsum("nij,jk,nik->ni", jac, cov, jac)))))
    return out


def _significance(
    problem: BundleProblem, state: BundleState, base: BoolArray, terms: list[tuple[str, ...]]
) -> list[FloatArray]:
    """Per camera, |estimate| / standard error of each of its terms at ``state``."""
    S, _ = reduced_camera_system(problem, state)
    _, covs = _solve(S, np.zeros(S.shape[0]), base, terms)
    sigma = robust_sigma(residuals(problem, state)[0])
    out = []
    for c, t in enumerate(terms):
        values = state.blocks[c, term_columns(t)]
        with np.errstate(divide="ignore", invalid="ignore"):
            out.append(np.abs(values) / (sigma * np.sqrt(np.diag(covs[c]))))
    return out


def choose_terms(
    problem: BundleProblem,
    state: BundleState,
    base: BoolArray,
    sizes: Sequence[tuple[int, int]],
    coverage: Sequence[float],
) -> tuple[list[LensChoice], BundleState]:
    """Fit the terms each camera's data determine (:data:`CANDIDATES`, :data:`MIN_T`).

    Each candidate is adjusted for every camera whose coverage allows it, together with
    the terms kept so far; a camera whose estimate of the candidate is below
    :data:`MIN_T` standard errors loses it (set back to zero) and the rest are adjusted
    once more without it.

    Parameters
    ----------
    problem : BundleProblem
        The adjustment (its ``free`` is changed).
    state : BundleState
        Current rig, distortion zero.
    base : ndarray of bool, shape (C, 15)
        Parameters adjusted besides distortion (poses, principal distances and points).
    sizes : sequence of (int, int)
        Image sizes (px).
    coverage : sequence of float
        Fraction of each camera's image the wand covered.

    Returns
    -------
    choices : list of LensChoice
        One per camera.
    state : BundleState
        Adjusted with the chosen terms.
    """
    C = len(coverage)
    kept: list[tuple[str, ...]] = [() for _ in range(C)]
    left_out: list[list[str]] = [[] for _ in range(C)]
    limit = ["" for _ in range(C)]

    def fit(terms: list[tuple[str, ...]], start: BundleState) -> BundleState:
        problem.free = base.copy()
        for c, t in enumerate(terms):
            problem.free[c, term_columns(t)] = True
        return adjust(problem, start, max_iterations=15, tolerance=1e-6)[0]

    for new, needs in CANDIDATES:
        eligible = []
        for c, cover in enumerate(coverage):
            short = [t for t in new if cover < MIN_COVERAGE[t]]
            if needs and needs not in kept[c]:
                left_out[c].append(f"{', '.join(new)} (needs {needs})")
            elif short:
                left_out[c].append(
                    f"{', '.join(new)} (the wand covered {100 * cover:.0f} % of the image, "
                    f"{', '.join(short)} need{'s' if len(short) == 1 else ''} >= "
                    f"{100 * max(MIN_COVERAGE[t] for t in short):.0f} %)"
                )
                limit[c] = limit[c] or "coverage"
            else:
                eligible.append(c)
        if eligible:
            trial = [
                tuple(t for t in ALL_TERMS if t in kept[c] or (c in eligible and t in new))
                for c in range(C)
            ]
            fitted = fit(trial, state)
            z = _significance(problem, fitted, base, trial)
            weak = [(c, max(float(z[c][trial[c].index(t)]) for t in new)) for c in eligible]
            weak = [(c, zc) for c, zc in weak if not zc >= MIN_T]
            # Weak estimates are set back to zero; the cameras keep the rest of the fit
            # (later stages adjust everything again).
            for c, z_new in weak:
                eligible.remove(c)
                fitted.blocks[c, term_columns(new)] = 0.0
                left_out[c].append(
                    f"{', '.join(new)} (estimate {z_new:.2g} standard errors from zero, "
                    f"needs >= {MIN_T:g})"
                )
                limit[c] = limit[c] or "conditioning"
            for c in eligible:
                kept[c] = trial[c]
            # Terms fitted together leave the others where they fit jointly: fit again
            # without the weak ones (once; the final stages adjust everything again).
            state = fit(kept, fitted) if weak else fitted
    S, _ = reduced_camera_system(problem, state)
    sds = edge_sd(S, base, state.blocks, sizes, kept)
    problem.free = base.copy()
    for c, t in enumerate(kept):
        problem.free[c, term_columns(t)] = True
    return [
        LensChoice(
            kept[c],
            sds[c],
            "not fitted: " + "; ".join(left_out[c]) if left_out[c] else "",
            limit[c],
        )
        for c in range(C)
    ], state


def lens_mode(distortion: str | Sequence[str]) -> tuple[str, tuple[str, ...]]:
    """``("auto", ())`` or the name of a fixed set (preset or ``"terms"``) and its terms."""
    if isinstance(distortion, str):
        if distortion == "auto":
            return "auto", ()
        if distortion in PRESETS:
            return distortion, PRESETS[distortion]
        raise CalibrationError(
            f"distortion {distortion!r}: expected auto, {', '.join(PRESETS)} or a list of terms"
        )
    unknown = set(distortion) - set(ALL_TERMS)
    if unknown:
        raise CalibrationError(f"unknown distortion term(s) {sorted(unknown)}")
    return "terms", tuple(t for t in ALL_TERMS if t in distortion)


def fit_fixed_terms(
    mode: str,
    terms: tuple[str, ...],
    problem: BundleProblem,
    state: BundleState,
    base: BoolArray,
    sizes: list[tuple[int, int]],
) -> tuple[list[LensChoice], BundleState]:
    """The terms asked for, adjusted for every camera, with their edge SD."""
    C = len(sizes)
    problem.free = base.copy()
    problem.free[:, term_columns(terms)] = True
    state = adjust(problem, state, max_iterations=40)[0]
    S, _ = reduced_camera_system(problem, state)
    sds = edge_sd(S, base, state.blocks, sizes, [terms] * C)
    reason = f"{', '.join(terms) or 'no terms'} as asked ({mode})"
    return [LensChoice(terms, sd, reason, "chosen") for sd in sds], state


def next_step(
    choice: LensChoice, problems: list[str], tried: set[tuple[str, ...]], cover: float
) -> LensChoice | None:
    """Another :data:`LADDER` step for a camera whose fitted model does not invert.

    First the next richer step the coverage allows (a strong barrel lens fitted with
    ``k1`` alone turns back before the image corners; ``k2`` may hold it), then the
    richest poorer step; None when every step has been tried.
    """
    index = LADDER.index(choice.terms) if choice.terms in LADDER else len(LADDER) - 1
    richer = [
        s
        for s in LADDER[index + 1 : index + 2]
        if s not in tried and all(cover >= MIN_COVERAGE[t] for t in s)
    ]
    poorer = [s for s in LADDER[:index][::-1] if s not in tried]
    options = richer + poorer
    if not options:
        return None
    step = options[0]
    change = (
        f"{', '.join(t for t in step if t not in choice.terms)} fitted"
        if len(step) > len(choice.terms)
        else f"{', '.join(t for t in choice.terms if t not in step)} not fitted"
    )
    return LensChoice(
        step,
        float("nan"),  # not estimated for a step taken after the fit
        f"{change}: with {', '.join(choice.terms)} the lens model could not be inverted over "
        f"the whole image ({problems[0]})",
        "inversion",
    )
