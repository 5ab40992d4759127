"""Type stubs for the compiled core (crates/imu_core, feature "python").

Arrays: ``t_ns`` int64 (N,); vectors float64 (N, 3); quaternions float64 (N, 4) in w,x,y,z order.
Inputs must be C-contiguous; outputs are fresh arrays that own Rust's buffers (no copy).
Errors: the classes of imu_learn.errors, raised directly by the core (pyo3 import_exception!), one
per core error kind; a missing file raises FileNotFoundError. Readers of IMU and ground-truth files
raise TooFewRowsError for a file with fewer than 2 rows (empty, header only, one sample or pose).
Inconsistent arguments raise InvalidInputError naming the argument (``horizons[1] = ...``), checked
before anything is allocated; memory that runs out for a huge batch is a MemoryError, never an abort.
Index arguments (_Idx) take a 1-d uint64 or int64 array or a list of ints; a negative entry is an
InvalidInputError (never wrapped to 2^64 - 1).
"""
from os import PathLike
from typing import Any, Dict, List, Optional, Sequence, Tuple, TypedDict, Union

import numpy as np
import numpy.typing as npt

__version__: str

_Path = Union[str, PathLike[str]]
_I64 = npt.NDArray[np.int64]
_Idx = Union[npt.NDArray[np.uint64], npt.NDArray[np.int64], Sequence[int]]
_F64 = npt.NDArray[np.float64]


class _GroundTruth(TypedDict):
    """A ground-truth reader's result: stamps, positions and w,x,y,z quaternions always; velocity and the
    biases where the file holds them (else None)."""

    t_ns: _I64
    p: _F64
    q_wxyz: _F64
    v: Optional[_F64]
    bias_gyro: Optional[_F64]
    bias_acc: Optional[_F64]


def read_asl_imu(path: _Path, allow_float_timestamps: bool = False) -> Tuple[_I64, _F64, _F64]:
    """ASL IMU CSV -> (t_ns, gyro, acc)."""

def read_asl_imu_header(path: _Path) -> str:
    """The file's first line, as written."""

def write_asl_imu(path: _Path, t_ns: _I64, gyro: _F64, acc: _F64, header: Optional[str] = None,
                  crlf: bool = False) -> None:
    """Write an ASL IMU CSV atomically (temp file + rename)."""

def read_asl_state(path: _Path, allow_float_timestamps: bool = False) -> _GroundTruth:
    """ASL state ground truth -> {t_ns, p, q_wxyz, v, bias_gyro, bias_acc}."""

def read_asl_pose(path: _Path, allow_float_timestamps: bool = False) -> _GroundTruth:
    """ASL pose ground truth (TUM-VI mocap0) -> {t_ns, p, q_wxyz, v=None, ...}."""

def read_asl_position(path: _Path, allow_float_timestamps: bool = False) -> Tuple[_I64, _F64]:
    """ASL position file (EuRoC leica0: t, p_RS_R) -> (t_ns (N,), p (N, 3))."""

def read_tum(path: _Path, allow_float_timestamps: bool = False) -> _GroundTruth:
    """TUM ground truth (8 columns, or 11 with velocity) -> {t_ns, p, q_wxyz, v, ...}. '#' comment
    lines and blank lines are skipped anywhere; stamps in seconds are exact (half to even past the
    ns)."""

def read_trajectory(
    path: _Path, layout: str = "tum", positions_only: bool = False, allow_float_timestamps: bool = False
) -> Dict[str, Optional[np.ndarray]]:
    """Trajectory (aiding) file -> {t_ns (N,) int64, p (N, 3), q_wxyz (N, 4) as in the file (not
    normalised) or None for positions only, lines (N,) int64: each row's 1-based line}. layout:
    ``tum`` (t tx ty tz qx qy qz qw, white space, seconds), ``csv`` (the same, commas; a header line of
    names is skipped), ``asl`` (timestamp [ns], px, py, pz, qw, qx, qy, qz). Comment lines, comments
    after a row and blank lines are skipped; rows have 8 columns, or 4 (t x y z) with positions_only;
    stamps in seconds are exact (half to even past the ns). Errors as read_tum's, each also carrying
    what it holds beyond its place: ``value`` (the field's text; the stamp [ns] for a TimestampError),
    ``previous`` (TimestampError), ``expected``/``found`` (ColumnCountError), ``found`` rows
    (TooFewRowsError); InvalidInputError for an unknown layout."""

def seconds_to_ns(text: str) -> int:
    """Decimal seconds -> integer ns by the readers' rule: exact decimal parsing, digits past the ns
    rounded half to even. ValueError for text that is not a number, OverflowError for NaN, infinity
    or a value outside the int64 ns range."""

def write_tum(path: _Path, t_ns: _I64, p: _F64, q_wxyz: _F64) -> None:
    """Write a TUM trajectory atomically."""

def read_kaist_imu(path: _Path, allow_float_timestamps: bool = False) -> Tuple[_I64, _F64, _F64]:
    """KAIST ``xsens_imu.csv`` -> (t_ns, gyro, acc)."""

def read_kaist_pose(path: _Path, allow_float_timestamps: bool = False) -> _GroundTruth:
    """KAIST ``global_pose.csv`` -> {t_ns, p, q_wxyz, v=None, ...}."""

def read_csv_columns(path: _Path, columns: str, time_unit: str, gyro_unit: str, acc_unit: str) -> Tuple[_I64, _F64, _F64]:
    """A user's IMU CSV -> (t_ns, gyro [rad/s], acc [m/s^2]). columns: the file's column order,
    ``t,gx,gy,gz,ax,ay,az`` with ``_`` for a column to skip (later columns are ignored); time_unit
    s|ms|us|ns (integer or float text, read exactly), gyro_unit rad/s|deg/s, acc_unit m/s2|g
    (9.80665). Delimiter (; , tab or whitespace), a header line and '#' comments are found in the
    file; blank lines are skipped. Errors name path:line:column and the field: ColumnCountError (a
    line shorter than the map), NotNumericError, NonFiniteError, TimestampError (not strictly increasing),
    TooFewRowsError; InvalidInputError for an unknown unit or a bad column map."""

def read_csv_columns_checked(
    path: _Path, columns: str, time_unit: str, gyro_unit: str, acc_unit: str, skip_bad_lines: bool = False
) -> Dict[str, Any]:
    """A user's IMU CSV read as read_csv_columns does, with what plausibility checks need -> {t_ns,
    gyro [rad/s], acc [m/s^2], skipped: [(line, problem)] (skip_bad_lines: lines too short for the map
    or with a field that is not a finite number, passed over instead of raising, each with the error
    it would have raised), names: [str] (the header's or a comment line's column names, [] without),
    fields: int (fields of the first row, a trailing delimiter not counted)}. Stamps out of order
    stay an error."""

def write_csv_columns(
    original: _Path, out: _Path, gyro: _F64, acc: _F64, columns: str, time_unit: str, gyro_unit: str, acc_unit: str,
    skip_bad_lines: bool = False,
) -> None:
    """Write ``out``: ``original`` (read as read_csv_columns_checked does, with skip_bad_lines) with its
    gyro and acc fields replaced by gyro [rad/s] / acc [m/s^2] (one row per sample), in the file's own
    units; header, comments, time, every other column and skipped lines keep their text. Atomic (temp
    file + rename)."""

def allan_deviation(
    samples: _F64, period_s: float, per_decade: int = 20, m: Optional[npt.NDArray[np.uint64]] = None
) -> Dict[str, np.ndarray]:
    """Overlapping Allan deviation of rate samples (N, k) of period period_s -> {m (T,) uint64 cluster
    sizes (default: per_decade log-spaced from 1 to N/2), tau_s (T,), n_clusters (T,) = N // m,
    rel_err (T,) = 1/sqrt(2 (N/m - 1)), adev (T, k)}. Cumulative sums, O(N) per cluster size, the
    GIL released."""

def allan_fit(tau_s: _F64, adev: _F64, rel_err: _F64) -> Dict[str, Any]:
    """Slope fits of each axis of adev (T, k) -> {white: {value (k,) N at tau = 1 s on the -1/2
    line, rel_err, tau_lo, tau_hi, points}, random_walk: {... K at tau = 3 s on the +1/2 line},
    bias_instability (k,) = min adev / 0.664, tau_bias, bias_rel_err, bias_observed (bool: the
    minimum is not the last usable point)}. NaN (points 0) where a line has no region."""

def align(
    imu_t_ns: _I64, gyro: _F64, acc: _F64, gt_t_ns: _I64, p: _F64, q_wxyz: _F64, v: Optional[_F64],
    max_gap_ns: int, min_segment_samples: int, velocity_half_window: int,
    imu_source: Optional[_Path] = None, gt_source: Optional[_Path] = None,
) -> Tuple[List[Dict[str, np.ndarray]], Dict[str, Any]]:
    """Ground truth onto IMU stamps -> (segments as dicts of t_ns/gyro/acc/p/v/q_wxyz, report).
    imu_source / gt_source: the files the arrays came from, named by the errors (NoOverlapError,
    AlignmentError: ``path`` = gt_source, ``imu_path`` = imu_source)."""

def derive_velocity(t_ns: _I64, p: _F64, half_window: int) -> _F64:
    """Velocity from positions by a local quadratic fit over +-half_window samples (at least 1); stamps
    strictly increasing and positions finite, else InvalidInputError."""

def preintegrate(t_ns: _I64, gyro: _F64, acc: _F64) -> Tuple[_F64, _F64, _F64, _F64]:
    """Cumulative (dq_wxyz, dv, dp, dt); row j covers [t_0, t_j]."""

def window_labels(
    t_ns: _I64, p: _F64, v: _F64, q_wxyz: _F64, window: int, stride: int, fractions: Sequence[float], gravity: float
) -> Dict[str, np.ndarray]:
    """Ground-truth labels -> {starts (W,), horizons (H,), dq_wxyz (W,H,4), dv, dp (W,H,3), dt (W,H)}."""

def integrate_windows(t_ns: _I64, gyro: _F64, acc: _F64, starts: _Idx, horizons: _Idx) -> Dict[str, np.ndarray]:
    """IMU-side increments in the layout of window_labels. Horizons in 1..N-1, every start + the
    longest horizon below N (InvalidInputError otherwise, even with no starts); no starts give
    empty (0, H, ...) arrays."""

def offset_rotation_angles(
    t_ns: _I64, gyro: _F64, starts: _Idx, horizons: _Idx, dq_ref: _F64, tau: float, period_ns: float,
) -> _F64:
    """Rotation residual angles [rad] (W*H,) of the windows (starts, horizons as window_labels lays
    them out; dq_ref (W*H, 4) their reference rotations) with the gyro linearly interpolated at
    t + tau * period_ns (ends held; np.interp's values bit for bit) and integrated by zero-order
    hold as integrate_windows does. Inputs checked as integrate_windows checks them."""

def filtfilt_section(x: _F64, sos: _F64) -> _F64:
    """x (N, C) float64 C-contiguous, N > 9, filtered by one second-order section sos (6,) = (b0, b1,
    b2, a0, a1, a2) forward and backward, each column alone: scipy.signal.sosfiltfilt for one section
    (odd padding of 9 samples, each pass started in the steady state of its first sample). A short x,
    a non-finite sos, a0 = 0 or a pole at z = 1 raise InvalidInputError."""

def rotation_window_sums(
    gyro: _F64, acc_g: _F64, dt: _F64, theta: _F64, horizons: _Idx, jacobian: bool,
) -> Dict[str, Optional[_F64]]:
    """The traditional fit's gyro rotations over B windows of W samples (gyro, acc_g (B, W, 3), dt
    (B, W) [s]) at theta (21,) = (M_g - I, b_g, G) row-major: per sample omega = M g - G a - M b,
    Q_k = Q_{k-1} Exp(omega dt). Returns {"q_wxyz": (B, H, 4) Q_{h-1} per horizon h, "sums": with
    jacobian (B, H, 9, 7) sum_{k<h} A_k[r, i] f_k[F] at [b, h, 3r + i, F], A_k = R(Q_k) J_r(omega dt) dt,
    f_k = (g_k, a_k, 1); else None}. Horizons in 1..W, any order; a non-finite theta, mismatched
    shapes or a horizon out of range raise InvalidInputError. See imu_learn.baselines.traditional."""

def velocity_window_sums(rates: _F64, acc: _F64, dt: _F64, horizons: _Idx) -> _F64:
    """The traditional fit's accelerometer sums over B windows of W samples (rates, the calibrated
    gyro rates [rad/s], and acc, (B, W, 3); dt (B, W) [s]): with the held rotations R_0 = I,
    R_{k+1} = R_k Exp(omega_k dt_k), T_m = sum_{j<m} dt_j, s_k = T_{k+1} - dt_k / 2 and the columns
    c_k = (a_k, 1, s_k a_k, s_k), returns (B, H, 9, 8) float64, sum_{k<h} R_k[r, i] dt_k c_k[F] at
    [b, h, 3r + i, F] for each horizon h. Horizons in 1..W, any order; mismatched shapes, arrays not
    C-contiguous or a horizon out of range raise InvalidInputError. See
    imu_learn.baselines.traditional (_VelResiduals); its numpy oracle imu_learn.core.numpy_reference."""

def increment_covariance(t_ns: _I64, gyro: _F64, acc: _F64, var: _F64, horizons: _Idx) -> _F64:
    """(H, 9, 9) covariance of (dtheta, dbeta, dgamma) after each horizon's number of intervals from
    sample 0 (the rows of preintegrate; horizon 0 is zero). var (N, 6): per-sample discrete-time
    variances, gyro then acc. See imu_learn.core.covariance."""

def interval_covariances(t_ns: _I64, gyro: _F64, acc: _F64, var: _F64, boundaries: _Idx) -> _F64:
    """(M - 1, 9, 9) covariance of each interval [t_b[i], t_b[i+1]] integrated from its own start, for
    strictly increasing sample indices boundaries (M,). See imu_learn.core.covariance."""

class SequenceSet:
    """Aligned sequences held in Rust: tuples (t_ns, gyro, acc, p, v, q_wxyz)."""

    def __init__(self, parts: List[Tuple[_I64, _F64, _F64, _F64, _F64, _F64]]) -> None: ...
    def __len__(self) -> int: ...
    def make_batch(
        self, window: int, batch_size: int, fractions: Sequence[float], gravity: float, seed: int,
        gyro_noise_density: float = 0.0, acc_noise_density: float = 0.0, gyro_bias_max: float = 0.0,
        acc_bias_max: float = 0.0, gyro_bias_walk: float = 0.0, acc_bias_walk: float = 0.0,
    ) -> Dict[str, np.ndarray]:
        """Augmented batch: imu (B,W,6), dt (B,W), dq_wxyz (B,H,4), dv/dp (B,H,3), label_dt (B,H),
        bias (B,W,6), seq_index (B,), start (B,), horizons (H,). A batch_size x window no allocation
        can hold is an InvalidInputError naming batch_size; memory that runs out, a MemoryError."""
    def eval_windows(self, window: int, stride: int, fractions: Sequence[float], gravity: float) -> Dict[str, np.ndarray]:
        """Every window at a fixed stride, no augmentation; layout of make_batch."""
