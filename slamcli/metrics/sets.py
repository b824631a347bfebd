"""Metrics of set-membership results (boxes per hypothesis, ``SolverResult.hypotheses``).

* **Soundness**: the fraction of true poses (all three coordinates, headings compared modulo 2π) and of true
  landmarks inside their boxes under the *true* correspondence's hypothesis. With errors inside the declared
  bounds it must be 1 — anything less is a bug (or a wrong declared bound).
* **Box widths**: mean/max widths of x, y, θ (poses) and x, y (landmarks) per hypothesis.
* **Hypotheses**: how many survive and how many are distinct up to relabelling of the landmarks
  (canonical association: labels renumbered by first appearance).
* **True correspondence survived**: some hypothesis groups the observations exactly like the truth
  (``truth.obs_landmark``), up to labels.
* **Point-inside fraction**: the fraction of another estimate's poses/landmarks (e.g. ``graph``) inside the
  boxes — set-membership vs least squares.

Pure functions: arrays in, numbers out.
"""

from __future__ import annotations

import numpy as np

from slamcli.types import BoxHypotheses

TWO_PI = 2.0 * np.pi


def canonical(assoc) -> tuple[int, ...]:
    """Association relabelled by order of first appearance (``-1`` stays ``-1``)."""
    first: dict[int, int] = {}
    return tuple(-1 if int(a) < 0 else first.setdefault(int(a), len(first)) for a in np.asarray(assoc).ravel())


def angle_in(theta, lo, hi, slack: float = 0.0) -> np.ndarray:
    """Is ``θ + 2πk`` in ``[lo − slack, hi + slack]`` for some integer k? (boxes keep headings unwrapped)."""
    theta, lo, hi = (np.asarray(a, float) for a in (theta, lo, hi))
    k = np.ceil((lo - slack - theta) / TWO_PI)
    return (theta + k * TWO_PI) <= hi + slack


def points_in_boxes(xy, lo, hi, slack: float = 0.0) -> np.ndarray:
    """``(K,)`` bool: point k inside box k (all coordinates)."""
    xy, lo, hi = (np.asarray(a, float) for a in (xy, lo, hi))
    return np.all((xy >= lo - slack) & (xy <= hi + slack), axis=-1)


def poses_in_boxes(poses_xyt, lo, hi, slack: float = 0.0) -> np.ndarray:
    """``(T+1,)`` bool: pose t inside box t (x, y directly, θ modulo 2π)."""
    poses_xyt, lo, hi = (np.asarray(a, float) for a in (poses_xyt, lo, hi))
    return points_in_boxes(poses_xyt[:, :2], lo[:, :2], hi[:, :2], slack) & angle_in(
        poses_xyt[:, 2], lo[:, 2], hi[:, 2], slack)


def true_hypothesis(hb: BoxHypotheses, obs_landmark) -> int:
    """Index of the hypothesis whose association equals the truth up to relabelling, or -1."""
    key = canonical(obs_landmark)
    for h in range(len(hb)):
        if canonical(hb.assoc[h]) == key:
            return h
    return -1


def landmark_map(assoc_h, obs_landmark) -> dict[int, int]:
    """Label of hypothesis h → true landmark index, from observations the two share."""
    out: dict[int, int] = {}
    for a, t in zip(np.asarray(assoc_h).ravel(), np.asarray(obs_landmark).ravel()):
        if a >= 0 and t >= 0:
            out.setdefault(int(a), int(t))
    return out


def soundness(hb: BoxHypotheses, h: int, true_poses_xyt, true_landmarks_xy, obs_landmark) -> dict:
    """Fraction of true poses and landmarks inside the boxes of hypothesis ``h`` (the true one)."""
    pin = poses_in_boxes(true_poses_xyt, hb.pose_lo[h], hb.pose_hi[h])
    m = landmark_map(hb.assoc[h], obs_landmark)
    lab = np.array(sorted(m), np.int64)
    tl = np.asarray(true_landmarks_xy, float)[[m[k] for k in lab]] if lab.size else np.zeros((0, 2))
    lin = points_in_boxes(tl, hb.landmark_lo[h, lab], hb.landmark_hi[h, lab]) if lab.size else np.zeros(0, bool)
    n = pin.size + lin.size
    return {"pose_inside": pin, "landmark_inside": lin,
            "soundness": float((pin.sum() + lin.sum()) / n) if n else float("nan")}


def box_widths(hb: BoxHypotheses, h: int) -> dict[str, float]:
    """Mean/max widths of hypothesis ``h``: poses x, y, θ and landmarks x, y (mean of x and y too)."""
    pw = hb.pose_hi[h] - hb.pose_lo[h]
    L = int(hb.n_landmarks[h])
    lw = hb.landmark_hi[h, :L] - hb.landmark_lo[h, :L]
    out = {}
    for i, c in enumerate("xyt"):
        out[f"pose_width_{c}_mean"] = float(pw[:, i].mean())
        out[f"pose_width_{c}_max"] = float(pw[:, i].max())
    for i, c in enumerate("xy"):
        out[f"landmark_width_{c}_mean"] = float(lw[:, i].mean()) if L else float("nan")
        out[f"landmark_width_{c}_max"] = float(lw[:, i].max()) if L else float("nan")
    out["landmark_width_mean"] = float(lw.mean()) if L else float("nan")
    return out


def n_distinct(hb: BoxHypotheses) -> int:
    """Hypotheses distinct up to relabelling of landmarks."""
    return len({canonical(hb.assoc[h]) for h in range(len(hb))})


def estimate_inside(hb: BoxHypotheses, h: int, poses_xyt, landmarks_xy=None, assoc=None,
                    slack: float = 1e-9) -> dict:
    """Fraction of another estimate inside hypothesis ``h``'s boxes (poses; landmarks matched through the
    shared observations ``assoc`` → labels of h). ``slack`` (m, rad) absorbs rounding: a least-squares
    solver that holds the known start with a tight prior lands ~1e-15 beside the degenerate start box."""
    pin = poses_in_boxes(poses_xyt, hb.pose_lo[h], hb.pose_hi[h], slack)
    out = {"pose_inside_fraction": float(pin.mean()), "pose_inside": pin}
    if landmarks_xy is not None and assoc is not None:
        m = landmark_map(hb.assoc[h], assoc)  # label of h -> row of the other estimate
        lab = np.array(sorted(m), np.int64)
        if lab.size:
            lin = points_in_boxes(np.asarray(landmarks_xy)[[m[k] for k in lab]], hb.landmark_lo[h, lab],
                                  hb.landmark_hi[h, lab], slack)
            out["landmark_inside_fraction"] = float(lin.mean())
            out["landmark_inside"] = lin
    return out


def set_metrics(hb: BoxHypotheses, true_poses_xyt, true_landmarks_xy, obs_landmark) -> dict:
    """The scalar set metrics of one result (JSON-clean)."""
    h_true = true_hypothesis(hb, obs_landmark)
    s: dict = {"n_hypotheses": len(hb), "n_hypotheses_distinct": n_distinct(hb),
               "true_correspondence_survived": bool(h_true >= 0), "true_hypothesis_index": int(h_true)}
    if h_true >= 0:
        snd = soundness(hb, h_true, true_poses_xyt, true_landmarks_xy, obs_landmark)
        s["soundness"] = snd["soundness"]
        s["soundness_poses"] = float(snd["pose_inside"].mean())
        s["soundness_landmarks"] = float(snd["landmark_inside"].mean()) if snd["landmark_inside"].size else None
        s.update({f"true_{k}": v for k, v in box_widths(hb, h_true).items()})
    else:
        s["soundness"] = None
    s.update({f"best_{k}": v for k, v in box_widths(hb, 0).items()})
    return s
