"""How the numbers after a graph file's measurement are read: one *convention* per file.

Tools share tags but not the meaning of the numbers (``EDGE2 i j dx dy dθ a b c d e f`` is TORO information
in a TORO file, g2o-ordered square-root information in an iSAM file, a covariance for GTSAM's ``load2D``).
A convention fixes, per tag, the **order** of a 3×3 symmetric matrix's six numbers (g2o's upper triangle
``[a11 a12 a13 a22 a23 a33]`` or TORO's ``[ff fs ss rr fr sr]``), what the matrix **is** (information ``Λ``,
covariance ``Σ = Λ⁻¹`` or square-root information ``R`` with ``Λ = RᵀR``), and whether landmark ids share
the pose **id space**:

==========  ============================================  ==============================  ==========
convention  pose-pose edges (EDGE_SE2, EDGE2, ODOMETRY)    landmark xy sightings           landmark ids
==========  ============================================  ==============================  ==========
g2o         information, g2o order (GTSAM's readG2o)      information                     shared
toro        information, TORO order                       information                     shared
gtsam       covariance, order from the zero pattern as    ``LANDMARK`` as ``load2D``:     own space
            ``load2D``'s AUTO (else refused)              bearing-range, σ_r = √c,
                                                          σ_b = √(c/10); others refused
isam        square-root information, g2o order            square-root information         own space
auto        per tag as its tool: EDGE_SE2 g2o info,       EDGE_SE2_XY, LANDMARK2 info;    own space for
            EDGE2 TORO info, ODOMETRY g2o covariance      LANDMARK covariance             LANDMARK/BR
==========  ============================================  ==============================  ==========

``BR i l b r σ_b σ_r`` (bearing, range and their σ) means the same in every convention.
"""

from __future__ import annotations

import numpy as np

CONVENTIONS = ("auto", "g2o", "toro", "gtsam", "isam")
EXPLICIT = CONVENTIONS[1:]

#: (order, kind) of a pose-pose edge's six numbers per tag, convention auto
_AUTO_POSE = {"EDGE_SE2": ("g2o", "information"), "EDGE2": ("toro", "information"),
              "ODOMETRY": ("g2o", "covariance")}
#: kind of a landmark xy sighting's three numbers per tag, convention auto
_AUTO_XY = {"EDGE_SE2_XY": "information", "LANDMARK2": "information", "LANDMARK": "covariance"}
_POSE = {"g2o": ("g2o", "information"), "toro": ("toro", "information"), "isam": ("g2o", "sqrt_information")}
_XY = {"g2o": "information", "toro": "information", "isam": "sqrt_information"}
#: |c_xx − c_yy| under which GTSAM's load2D takes a LANDMARK covariance for c·I
GTSAM_ISOTROPIC_TOL = 1e-4
#: the range at which GTSAM's load2D takes a LANDMARK covariance to describe the uncertainty, m
GTSAM_LANDMARK_RANGE = 10.0


class ConventionError(ValueError):
    """A matrix the convention cannot read; the message names the reading and the alternatives."""


def separate_landmark_ids(convention: str, sighting_tags: set[str]) -> bool:
    """Do landmark ids have their own id space (module docstring table)?"""
    if convention in ("gtsam", "isam"):
        return True
    if convention == "auto":
        return bool(sighting_tags) and sighting_tags <= {"LANDMARK", "BR"}
    return False


def _sym3(v, order: str) -> np.ndarray:
    if order == "toro":
        ff, fs, ss, rr, fr, sr = v
        return np.array([[ff, fs, fr], [fs, ss, sr], [fr, sr, rr]], float)
    a11, a12, a13, a22, a23, a33 = v
    return np.array([[a11, a12, a13], [a12, a22, a23], [a13, a23, a33]], float)


def _upper3(v) -> np.ndarray:
    a11, a12, a13, a22, a23, a33 = v
    return np.array([[a11, a12, a13], [0.0, a22, a23], [0.0, 0.0, a33]], float)


def _is_pd(m: np.ndarray) -> bool:
    """Finite, positive definite, and with a finite inverse (σ = 1e-200 squares to 0, σ = 1e200 to inf)."""
    if not np.all(np.isfinite(m)):
        return False
    eig = np.linalg.eigvalsh(0.5 * (m + m.T))
    with np.errstate(divide="ignore", over="ignore"):
        return bool(np.all(eig > 0) and np.all(np.isfinite(1.0 / eig)))


def _cov_info(m: np.ndarray, kind: str, upper) -> tuple[np.ndarray, np.ndarray] | None:
    """``(Σ, Λ)`` of a matrix read as ``kind``; None when it is not positive definite (or R is singular)."""
    if kind == "sqrt_information":
        if np.any(np.diag(upper) == 0) or not np.all(np.isfinite(upper)):
            return None
        info = upper.T @ upper
        return np.linalg.inv(info), info
    if not _is_pd(m):
        return None
    return (m, np.linalg.inv(m)) if kind == "covariance" else (np.linalg.inv(m), m)


def gtsam_pose_order(v) -> str | None:
    """The 3×3 layout GTSAM's ``load2D`` (noise format AUTO) sees in six numbers: ``"toro"`` for the pattern
    ``[a 0 b c 0 0]``, ``"g2o"`` for ``[a 0 0 b 0 c]`` (a, b, c ≠ 0), otherwise None (it refuses)."""
    nz = [x != 0.0 for x in v]
    if nz == [True, False, True, True, False, False]:
        return "toro"
    if nz == [True, False, False, True, False, True]:
        return "g2o"
    return None


def pose_reading(tag: str, convention: str, v) -> tuple[str, str] | None:
    """``(order, kind)`` of a pose-pose edge's six numbers ``v`` (None: gtsam cannot tell the layout)."""
    if convention == "auto":
        return _AUTO_POSE[tag]
    if convention == "gtsam":
        order = gtsam_pose_order(v)
        return None if order is None else (order, "covariance")
    return _POSE[convention]


def describe(order: str, kind: str) -> str:
    return f"{kind.replace('_', '-')}, {order} order"


def pose_matrix(tag: str, v, convention: str) -> tuple[np.ndarray, np.ndarray, str]:
    """``(Σ, Λ, reading)`` of a pose-pose edge's six numbers ``v`` under ``convention``.

    Raises ConventionError naming the reading and the conventions under which the numbers are valid.
    """
    reading = pose_reading(tag, convention, v)
    if reading is None:
        raise ConventionError(
            f"{tag} matrix {list(v)} has no diagonal layout GTSAM's load2D recognises (convention gtsam)"
            + _alternatives(tag, v, convention))
    order, kind = reading
    got = _cov_info(_sym3(v, order), kind, _upper3(v) if kind == "sqrt_information" else None)
    if got is None:
        raise ConventionError(f"{tag} matrix is not positive definite read as {describe(order, kind)} "
                              f"(convention {convention})" + _alternatives(tag, v, convention))
    return got[0], got[1], describe(order, kind)


def _alternatives(tag: str, v, convention: str) -> str:
    """``; it reads as … under --convention X`` for the explicit conventions that read ``v`` validly."""
    ok = []
    for c in EXPLICIT:
        if c == convention:
            continue
        r = pose_reading(tag, c, v)
        if r is not None and _cov_info(_sym3(v, r[0]), r[1], _upper3(v)) is not None:
            ok.append(f"--convention {c} ({describe(*r)})")
    return ("; valid under " + " or ".join(ok)) if ok else "; no convention reads it as positive definite"


def xy_matrix(tag: str, v, convention: str) -> tuple[np.ndarray, np.ndarray, str]:
    """``(Σ, Λ, reading)`` over the offset ``(x, y)`` of a landmark sighting's three numbers ``v``."""
    kind = _AUTO_XY[tag] if convention == "auto" else _XY[convention]
    a11, a12, a22 = v
    m = np.array([[a11, a12], [a12, a22]], float)
    got = _cov_info(m, kind, np.array([[a11, a12], [0.0, a22]]))
    if got is None:
        ok = [f"--convention {c} ({_XY[c].replace('_', '-')})" for c in ("g2o", "isam")
              if c != convention and _cov_info(m, _XY[c], np.array([[a11, a12], [0.0, a22]])) is not None]
        raise ConventionError(f"{tag} matrix is not positive definite read as {kind.replace('_', '-')} "
                              f"(convention {convention})"
                              + ("; valid under " + " or ".join(ok) if ok else ""))
    return got[0], got[1], kind.replace("_", "-")


def gtsam_landmark_sigmas(v) -> tuple[float, float]:
    """``(σ_bearing, σ_range)`` GTSAM's ``load2D`` gives a ``LANDMARK`` covariance ``[c_xx c_xy c_yy]``:
    ``σ_r = √c_xx``, ``σ_b = √(c_xx / 10)`` (the covariance taken at 10 m range). Only ``c·I`` is accepted
    (GTSAM substitutes σ = 1 for anything else)."""
    cxx, cxy, cyy = v
    if not (cxx > 0 and abs(cxx - cyy) < GTSAM_ISOTROPIC_TOL and cxy == 0):
        raise ConventionError(
            f"LANDMARK covariance {list(v)} is not c·I: GTSAM's load2D (convention gtsam) replaces it by "
            "σ = 1; read it as an xy covariance with --convention auto, or information with --convention g2o")
    return float(np.sqrt(cxx / GTSAM_LANDMARK_RANGE)), float(np.sqrt(cxx))
