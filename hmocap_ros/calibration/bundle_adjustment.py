"""Bundle adjustment of all camera poses and board poses (and optionally the intrinsics).

Minimises the reprojection error of every observed board corner (Triggs et al., "Bundle
adjustment - a modern synthesis", 2000) with ``scipy.optimize.least_squares`` (trust-region
reflective, LSMR on a sparse Jacobian): the residual of an observation depends on its camera's
6 pose parameters (and 9 intrinsics: fx, fy, cx, cy, k1, k2, p1, p2, k3 when refined) and its
board pose's 6 parameters, which ``jac_sparsity`` tells the finite differencing. A robust loss
(soft L1, 1 px scale) bounds the pull of mis-detected corners; observations further than
``outlier_px`` from their projection after a first pass are dropped and the problem is solved
again. The reference camera's pose is held at the identity (the gauge); the board's known
square size fixes the scale.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import coo_matrix

from hmocap_ros.calibration.observations import Observations
from hmocap_ros.geometry.distortion import distort_xy
from hmocap_ros.geometry.rotations import matrix_to_rotvec, rotvec_to_matrix

__all__ = ["BundleResult", "project_observations", "bundle_adjust"]

_N_INTR = 9


@dataclass(frozen=True, eq=False)
class BundleResult:
    """Refined world (reference camera) -> camera ``R_cam, t_cam`` (M, ...), board -> world
    ``R_board, t_board`` (P, ...), intrinsics ``K`` (M, 3, 3), ``D`` (M, 5), the observations
    kept and their residuals (N, 2) in pixels."""

    R_cam: np.ndarray
    t_cam: np.ndarray
    R_board: np.ndarray
    t_board: np.ndarray
    K: np.ndarray
    D: np.ndarray
    observations: Observations
    residuals: np.ndarray
    n_dropped: int

    def rms_per_camera(self) -> np.ndarray:
        """(M,) RMS reprojection error (px) per camera, NaN for a camera without observations."""
        sq = np.sum(self.residuals ** 2, axis=1)
        cam = self.observations.camera
        n = np.bincount(cam, minlength=len(self.K))
        total = np.bincount(cam, weights=sq, minlength=len(self.K))
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.sqrt(total / n)


def project_observations(obs: Observations, corner_points, R_cam, t_cam, R_board, t_board, K, D) -> np.ndarray:
    """(N, 2) pixels where each observation's corner projects."""
    X = corner_points[obs.corner]
    Xw = np.einsum("nij,nj->ni", R_board[obs.pose], X) + t_board[obs.pose]
    Xc = np.einsum("nij,nj->ni", R_cam[obs.camera], Xw) + t_cam[obs.camera]
    x, y = Xc[:, 0] / Xc[:, 2], Xc[:, 1] / Xc[:, 2]
    d = D[obs.camera]
    d8 = (d[:, 0], d[:, 1], d[:, 2], d[:, 3], d[:, 4], 0.0, 0.0, 0.0)
    xd, yd = distort_xy(x, y, d8)
    k = K[obs.camera]
    return np.stack([k[:, 0, 0] * xd + k[:, 0, 2], k[:, 1, 1] * yd + k[:, 1, 2]], axis=1)


class _Problem:
    """Parameter vector layout: [cameras but the reference: 6 each][boards: 6 each][intrinsics]."""

    def __init__(self, obs, corner_points, ref, K, D, refine_intrinsics):
        self.obs, self.points, self.ref = obs, corner_points, ref
        self.K, self.D = K, D
        self.M, self.P = obs.n_cameras, obs.n_poses
        self.free = [c for c in range(self.M) if c != ref]
        self.cam_slot = np.full(self.M, -1)
        self.cam_slot[self.free] = np.arange(len(self.free))
        self.n_cam = 6 * len(self.free)
        self.n_board = 6 * self.P
        self.refine_intrinsics = refine_intrinsics
        self.n = self.n_cam + self.n_board + (_N_INTR * self.M if refine_intrinsics else 0)

    def pack(self, R_cam, t_cam, R_board, t_board):
        cams = np.concatenate([matrix_to_rotvec(R_cam[self.free]), t_cam[self.free]], axis=1)
        boards = np.concatenate([matrix_to_rotvec(R_board), t_board], axis=1)
        parts = [cams.ravel(), boards.ravel()]
        if self.refine_intrinsics:
            intr = np.concatenate([self.K[:, 0, 0, None], self.K[:, 1, 1, None], self.K[:, 0, 2, None],
                                   self.K[:, 1, 2, None], self.D[:, :5]], axis=1)
            parts.append(intr.ravel())
        return np.concatenate(parts)

    def unpack(self, x):
        cams = x[:self.n_cam].reshape(-1, 6)
        boards = x[self.n_cam:self.n_cam + self.n_board].reshape(-1, 6)
        R_cam = np.repeat(np.eye(3)[None], self.M, axis=0)
        t_cam = np.zeros((self.M, 3))
        R_cam[self.free] = rotvec_to_matrix(cams[:, :3])
        t_cam[self.free] = cams[:, 3:]
        K, D = self.K.copy(), self.D.copy()
        if self.refine_intrinsics:
            intr = x[self.n_cam + self.n_board:].reshape(self.M, _N_INTR)
            K[:, 0, 0], K[:, 1, 1], K[:, 0, 2], K[:, 1, 2] = intr[:, 0], intr[:, 1], intr[:, 2], intr[:, 3]
            D = intr[:, 4:].copy()
        return R_cam, t_cam, rotvec_to_matrix(boards[:, :3]), boards[:, 3:], K, D

    def residuals(self, x):
        R_cam, t_cam, R_board, t_board, K, D = self.unpack(x)
        proj = project_observations(self.obs, self.points, R_cam, t_cam, R_board, t_board, K, D)
        return (proj - self.obs.pixels).ravel()

    def sparsity(self):
        obs = self.obs
        n_obs = len(obs.camera)
        rows, cols = [], []
        row = np.repeat(np.arange(n_obs), 2) * 2 + np.tile([0, 1], n_obs)  # both residuals of each
        obs_of_row = np.repeat(np.arange(n_obs), 2)
        slot = self.cam_slot[obs.camera][obs_of_row]
        has = slot >= 0
        for j in range(6):
            rows.append(row[has])
            cols.append(6 * slot[has] + j)
            rows.append(row)
            cols.append(self.n_cam + 6 * obs.pose[obs_of_row] + j)
        if self.refine_intrinsics:
            for j in range(_N_INTR):
                rows.append(row)
                cols.append(self.n_cam + self.n_board + _N_INTR * obs.camera[obs_of_row] + j)
        rows, cols = np.concatenate(rows), np.concatenate(cols)
        return coo_matrix((np.ones(len(rows), np.int8), (rows, cols)), shape=(2 * n_obs, self.n)).tocsr()


def _solve(problem: _Problem, x0: np.ndarray, max_nfev: int) -> np.ndarray:
    result = least_squares(problem.residuals, x0, jac_sparsity=problem.sparsity(), method="trf",
                           tr_solver="lsmr", loss="soft_l1", f_scale=1.0, x_scale="jac",
                           max_nfev=max_nfev, xtol=1e-10, ftol=1e-10)
    return result.x


def bundle_adjust(obs: Observations, corner_points: np.ndarray, ref: int, R_cam, t_cam, R_board,
                  t_board, K, D, refine_intrinsics: bool = False, outlier_px: float = 3.0,
                  max_nfev: int = 100) -> BundleResult:
    """Refine cameras and board poses (module docstring) from the initial estimates; ``K``
    (M, 3, 3) and ``D`` (M, 5) are held unless ``refine_intrinsics``."""
    D = np.pad(np.asarray(D, float), ((0, 0), (0, max(0, 5 - np.shape(D)[1]))))[:, :5]
    K = np.asarray(K, float)
    problem = _Problem(obs, corner_points, ref, K, D, refine_intrinsics)
    x = _solve(problem, problem.pack(R_cam, t_cam, R_board, t_board), max_nfev)
    residual = problem.residuals(x).reshape(-1, 2)
    keep = np.linalg.norm(residual, axis=1) <= outlier_px
    n_dropped = int((~keep).sum())
    if n_dropped:
        problem = _Problem(obs.subset(keep), corner_points, ref, K, D, refine_intrinsics)
        x = _solve(problem, x, max_nfev)
    R_cam, t_cam, R_board, t_board, K, D = problem.unpack(x)
    return BundleResult(R_cam, t_cam, R_board, t_board, K, D, problem.obs,
                        problem.residuals(x).reshape(-1, 2), n_dropped)
