"""The MRCLAM robots' camera, measured from their logs: field of view, range limit and noise.

    python -m lfmdr_gym.datasets.camera_model [RUN_DIR ...]   (default: the runs
        ../shared/data/mrclam/MRCLAM_Dataset* beside the project)

The figures behind :data:`lfmdr_gym.sim.camera.CAMERA_PRESET` (``LFMDR-Camera-v0``). The runs hold
the landmarks' motion-capture ground truth but not the robots' poses, so the geometry a measurement
is checked against comes from the image itself: every camera image that read three or more landmarks
fixes the robot's pose (x, y, heading) by a robust least-squares fit of its own ranges and bearings
to the landmarks' true positions (three unknowns, six or more readings), and each reading's residual
against that pose is *studentised*, divided by ``sqrt(1 - h)`` with ``h`` its leverage in the fit,
so that what the fit absorbed is given back and the spread is the sensor's, not the fit's. The fit
weighs range and bearing by their spreads, which are re-estimated from the residuals and the fit
repeated until they settle. Spreads are robust (1.4826 x the median absolute deviation), so the few
gross misreads do not inflate them.

* field of view: twice the largest ``|bearing|`` logged (the image's edges clip it);
* range limit: the 99th percentile of the logged ranges (the camera reads no barcode farther);
* bearing noise: the robust spread of the bearing residuals;
* range noise: the robust spread of the range residuals of readings no farther than
  ``near`` (default 3.54 m, the diagonal of the simulated 2.5 m arena, the distances the
  simulation has); it grows with distance, so the spread is also printed per range bin.

Not modelled by the environment, printed for the record: the least range (the 1st percentile:
nearer barcodes do not fit in the image) and the biases (median residuals).
"""

from __future__ import annotations

import argparse
import math
import os
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

from lfmdr_gym.datasets.mrclam import MRCLAMDataWarning, read_run

__all__ = ["CameraModel", "image_residuals", "measure_camera"]

NEAR = 2.5 * math.sqrt(2.0)
"""Default ``near`` [m]: the simulated arena's diagonal (2.5 m side), its longest distance."""

RANGE_BINS = (0.0, 1.5, 2.5, 3.5, 5.0, 7.0, math.inf)
"""Edges [m] of the range bins the range noise is also printed for."""

_MAD = 1.4826  # robust standard deviation of a Gaussian from its median absolute deviation


def _robust_sd(x: np.ndarray) -> float:
    x = np.asarray(x, dtype=float)
    return float(_MAD * np.median(np.abs(x - np.median(x)))) if x.size else math.nan


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2.0 * np.pi) - np.pi


def _predict(pose: np.ndarray, landmarks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    d = landmarks - pose[:2]
    return np.hypot(d[:, 0], d[:, 1]), np.arctan2(d[:, 1], d[:, 0]) - pose[2]


def _initial_pose(landmarks: np.ndarray, r: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The rigid motion taking the readings' robot-frame points onto the landmarks (2-D Kabsch)."""
    local = np.column_stack([r * np.cos(b), r * np.sin(b)])
    lc, wc = local.mean(axis=0), landmarks.mean(axis=0)
    h = (local - lc).T @ (landmarks - wc)
    angle = math.atan2(h[0, 1] - h[1, 0], h[0, 0] + h[1, 1])
    rot = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    return np.array([*(wc - rot @ lc), angle])


def _fit_image(landmarks, r, b, sd_r, sd_b):
    """Studentised (range, bearing) residuals of one image's readings against its fitted pose."""
    def whitened(pose):
        pr, pb = _predict(pose, landmarks)
        return np.concatenate([(r - pr) / sd_r, _wrap(b - pb) / sd_b])

    fit = least_squares(whitened, _initial_pose(landmarks, r, b), loss="soft_l1", f_scale=3.0)
    J = fit.jac
    try:
        hat = np.einsum("ij,jk,ik->i", J, np.linalg.inv(J.T @ J), J)
    except np.linalg.LinAlgError:
        return None
    res = whitened(fit.x) / np.sqrt(np.clip(1.0 - hat, 1e-6, None))
    k = len(r)
    return res[:k] * sd_r, res[k:] * sd_b


def image_residuals(run_dirs: Sequence[str | os.PathLike], *, min_landmarks: int = 3,
                    rounds: int = 4) -> dict[str, np.ndarray]:
    """Studentised residuals of every reading in an image of ``min_landmarks`` or more landmarks:
    ``{"range": measured range, "range_residual", "bearing_residual", "images": count}``
    (residual = measured - predicted from the image's fitted pose), pooled over the runs."""
    images = []
    for run_dir in run_dirs:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", MRCLAMDataWarning)  # the known DS1 fix is applied
            run = read_run(run_dir)
        order = np.argsort(run.image, kind="stable")
        img, obs = run.image[order], run.obs[order]
        starts = np.flatnonzero(np.r_[True, img[1:] != img[:-1]])
        for s, e in zip(starts, np.r_[starts[1:], len(img)], strict=True):
            rows = obs[s:e]
            li = rows[:, 2].astype(int)
            if e - s >= min_landmarks and np.unique(li).size == e - s:
                images.append((run.truth[li], rows[:, 3], rows[:, 4]))
    if not images:
        raise ValueError(f"no camera image with {min_landmarks} or more distinct landmarks in "
                         f"{[str(d) for d in run_dirs]}")
    sd_r, sd_b = 0.05, 0.01  # starting weights [m], [rad]; re-estimated each round
    for _ in range(rounds):
        fits = [(im[1], f) for im in images if (f := _fit_image(*im, sd_r, sd_b)) is not None]
        res_r = np.concatenate([f[0] for _, f in fits])
        res_b = np.concatenate([f[1] for _, f in fits])
        sd_r, sd_b = _robust_sd(res_r), _robust_sd(res_b)
    return {"range": np.concatenate([r for r, _ in fits]), "range_residual": res_r,
            "bearing_residual": res_b, "images": np.array(len(fits))}


@dataclass(frozen=True)
class CameraModel:
    """The camera's figures (lengths in metres, angles in degrees); see the module docstring."""

    runs: tuple[str, ...]
    readings: int
    images_fitted: int
    readings_fitted: int
    fov_deg: float
    max_range: float
    min_range: float
    bearing_noise_deg: float
    bearing_bias_deg: float
    range_noise: float
    range_noise_all: float
    range_bias: float
    near: float
    range_noise_by_bin: tuple[tuple[float, float, int, float], ...]
    per_run: tuple[tuple[str, float, float], ...] = ()

    def preset(self) -> dict[str, float]:
        """The env keywords of ``LFMDR-Camera-v0`` these figures give (rounded as printed)."""
        return {"fov_deg": round(self.fov_deg, 1), "max_range": round(self.max_range, 2),
                "bearing_noise_deg": round(self.bearing_noise_deg, 2),
                "range_noise": round(self.range_noise, 3)}

    def report(self) -> str:
        lines = [
            f"runs: {', '.join(self.runs)}; {self.readings} landmark readings; "
            f"{self.images_fitted} images of 3+ landmarks fitted ({self.readings_fitted} readings)",
            f"field of view: {self.fov_deg:.1f} deg (twice the largest |bearing|)",
            f"range limit: {self.max_range:.2f} m (99th percentile of the ranges); least range "
            f"{self.min_range:.2f} m (1st percentile; not modelled)",
            f"bearing noise: {self.bearing_noise_deg:.2f} deg (robust sd of the residuals; bias "
            f"{self.bearing_bias_deg:+.2f} deg, not modelled)",
            f"range noise: {self.range_noise:.3f} m at ranges <= {self.near:.2f} m "
            f"({self.range_noise_all:.3f} m over all ranges; bias {self.range_bias:+.3f} m, not "
            "modelled)",
            "range noise by range: " + "; ".join(
                f"{lo:g}-{hi:g} m: {sd:.3f} m (n={n})" for lo, hi, n, sd in self.range_noise_by_bin),
            "per run (bearing noise, range noise up to near): " + "; ".join(
                f"{name}: {b:.2f} deg, {r:.3f} m" for name, b, r in self.per_run),
            "LFMDR-Camera-v0 keywords: " + ", ".join(f"{k}={v}" for k, v in self.preset().items()),
        ]
        return "\n".join(lines)


def measure_camera(run_dirs: Sequence[str | os.PathLike], *, near: float = NEAR) -> CameraModel:
    """The camera's field of view, range limit and noise from MRCLAM runs (module docstring)."""
    run_dirs = [Path(d) for d in run_dirs]
    if not run_dirs:
        raise ValueError("measure_camera needs at least one MRCLAM run directory")
    ranges, bearings = [], []
    for d in run_dirs:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", MRCLAMDataWarning)
            run = read_run(d)
        ranges.append(run.obs[:, 3])
        bearings.append(run.obs[:, 4])
    ranges, bearings = np.concatenate(ranges), np.concatenate(bearings)
    each = [image_residuals([d]) for d in run_dirs]  # each run's own weights, then pooled
    r, rr, rb = (np.concatenate([e[k] for e in each])
                 for k in ("range", "range_residual", "bearing_residual"))
    per_run = tuple((d.name, float(np.degrees(_robust_sd(e["bearing_residual"]))),
                     _robust_sd(e["range_residual"][e["range"] <= near]))
                    for d, e in zip(run_dirs, each, strict=True))
    bins = []
    for lo, hi in zip(RANGE_BINS[:-1], RANGE_BINS[1:], strict=True):
        sel = (r > lo) & (r <= hi)
        if sel.any():
            bins.append((lo, hi, int(sel.sum()), _robust_sd(rr[sel])))
    return CameraModel(
        runs=tuple(d.name for d in run_dirs), readings=int(ranges.size),
        images_fitted=sum(int(e["images"]) for e in each), readings_fitted=int(r.size),
        fov_deg=float(2.0 * np.degrees(np.abs(bearings).max())),
        max_range=float(np.quantile(ranges, 0.99)), min_range=float(np.quantile(ranges, 0.01)),
        bearing_noise_deg=float(np.degrees(_robust_sd(rb))),
        bearing_bias_deg=float(np.degrees(np.median(rb))),
        range_noise=_robust_sd(rr[r <= near]), range_noise_all=_robust_sd(rr),
        range_bias=float(np.median(rr)), near=float(near), range_noise_by_bin=tuple(bins),
        per_run=per_run,
    )


def _default_runs() -> list[Path]:
    """The runs in ``../shared/data/mrclam`` beside the project (or the working directory)."""
    project = Path(__file__).resolve().parents[2]
    for root in (project / ".." / "shared" / "data" / "mrclam",
                 Path.cwd() / ".." / "shared" / "data" / "mrclam"):
        runs = sorted(root.glob("MRCLAM_Dataset*"))
        if runs:
            return runs
    return []


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="*", metavar="RUN_DIR", help="MRCLAM run directories")
    ap.add_argument("--near", type=float, default=NEAR,
                    help="largest range [m] of the range-noise figure the preset takes")
    args = ap.parse_args(argv)
    runs = [Path(r) for r in args.runs] or _default_runs()
    if not runs:
        ap.error("no MRCLAM run directories given and none found in ../shared/data/mrclam")
    print(measure_camera(runs, near=args.near).report())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
