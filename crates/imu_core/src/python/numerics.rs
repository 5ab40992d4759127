//! Alignment, integration, covariance, labels, batches and the traditional fit's rotation and
//! velocity sums.

use numpy::ndarray::Array4;
use numpy::{
    IntoPyArray, PyArray2, PyArray3, PyArray4, PyArrayDyn, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2,
    PyReadonlyArray3, PyUntypedArrayMethods,
};
use std::path::PathBuf;
use std::sync::LazyLock;

use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::align::{self as core_align, AlignOptions, Sources};
use crate::batch::{self, AugmentConfig, Batch, BatchConfig, BatchMut, BatchPlan};
use crate::covariance::{self, Cov9, Var6};
use crate::error::ImuError;
use crate::filter;
use crate::integrate::{self, PreintegratedMut};
use crate::labels::{self, GroundTruthView, Labels, LabelsMut};
use crate::offset;
use crate::python::arrays::{
    flat_mut, out1, out2, out2_flat, out3, out3_flat, pooled_arrays, rows, rows_mut, slice1, try_zeroed, zeros,
    BufferPool,
};
use crate::python::errors::{alignment_to_py, to_py};
use crate::rotsums::{self, SUM_COLS, SUM_ROWS, THETA_LEN, VEL_COLS};
use crate::types::Vec3;
use crate::types::{GroundTruth, ImuSamples, Sequence};

type Arr2<'py> = Bound<'py, PyArray2<f64>>;
type ArrD<'py> = Bound<'py, PyArrayDyn<f64>>;

fn seq_dict(py: Python<'_>, s: Sequence) -> PyResult<Bound<'_, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("t_ns", out1(py, s.t_ns))?;
    d.set_item("gyro", out2(py, s.gyro)?)?;
    d.set_item("acc", out2(py, s.acc)?)?;
    d.set_item("p", out2(py, s.p)?)?;
    d.set_item("v", out2(py, s.v)?)?;
    d.set_item("q_wxyz", out2(py, s.q_wxyz)?)?;
    Ok(d)
}

#[pyfunction]
#[allow(clippy::too_many_arguments)]
#[pyo3(signature = (imu_t_ns, gyro, acc, gt_t_ns, p, q_wxyz, v, max_gap_ns, min_segment_samples, velocity_half_window, imu_source=None, gt_source=None))]
fn align<'py>(
    py: Python<'py>,
    imu_t_ns: PyReadonlyArray1<'py, i64>,
    gyro: PyReadonlyArray2<'py, f64>,
    acc: PyReadonlyArray2<'py, f64>,
    gt_t_ns: PyReadonlyArray1<'py, i64>,
    p: PyReadonlyArray2<'py, f64>,
    q_wxyz: PyReadonlyArray2<'py, f64>,
    v: Option<PyReadonlyArray2<'py, f64>>,
    max_gap_ns: i64,
    min_segment_samples: usize,
    velocity_half_window: usize,
    imu_source: Option<PathBuf>,
    gt_source: Option<PathBuf>,
) -> PyResult<(Bound<'py, PyList>, Bound<'py, PyDict>)> {
    let imu = ImuSamples {
        t_ns: slice1(&imu_t_ns, "imu_t_ns")?.to_vec(),
        gyro: rows::<3>(&gyro, "gyro")?.to_vec(),
        acc: rows::<3>(&acc, "acc")?.to_vec(),
    };
    let gt = GroundTruth {
        t_ns: slice1(&gt_t_ns, "gt_t_ns")?.to_vec(),
        p: rows::<3>(&p, "p")?.to_vec(),
        q_wxyz: rows::<4>(&q_wxyz, "q_wxyz")?.to_vec(),
        v: v.as_ref().map(|v| rows::<3>(v, "v").map(|r| r.to_vec())).transpose()?,
        ..Default::default()
    };
    let opts = AlignOptions {
        max_gap_ns,
        min_segment_samples,
        velocity_half_window,
    };
    let sources = Sources {
        imu: imu_source,
        gt: gt_source,
    };
    let (seqs, report) = py
        .allow_threads(|| core_align::align_from(&imu, &gt, &opts, &sources))
        .map_err(|e| alignment_to_py(e, &sources))?;
    let list = PyList::empty(py);
    for s in seqs {
        list.append(seq_dict(py, s)?)?;
    }
    let r = PyDict::new(py);
    r.set_item("imu_samples", report.imu_samples)?;
    r.set_item("dropped_before", report.dropped_before)?;
    r.set_item("dropped_after", report.dropped_after)?;
    r.set_item("dropped_in_gaps", report.dropped_in_gaps)?;
    r.set_item("dropped_short", report.dropped_short)?;
    r.set_item("gaps_ns", report.gaps.clone())?;
    r.set_item(
        "segments_ns",
        report
            .segments
            .iter()
            .map(|s| (s.start_ns, s.end_ns, s.samples))
            .collect::<Vec<_>>(),
    )?;
    r.set_item("velocity_derived", report.velocity_derived)?;
    Ok((list, r))
}

#[pyfunction]
fn derive_velocity<'py>(
    py: Python<'py>,
    t_ns: PyReadonlyArray1<'py, i64>,
    p: PyReadonlyArray2<'py, f64>,
    half_window: usize,
) -> PyResult<Arr2<'py>> {
    let (t, p) = (slice1(&t_ns, "t_ns")?, rows::<3>(&p, "p")?);
    if t.len() != p.len() {
        return Err(to_py(ImuError::invalid("t_ns and p differ in length")));
    }
    if half_window == 0 {
        return Err(to_py(ImuError::invalid(
            "half_window = 0: the quadratic fit needs at least 1 sample each side",
        )));
    }
    crate::integrate::check_stamps(t).map_err(to_py)?;
    if let Some(i) = p.iter().position(|r| r.iter().any(|x| !x.is_finite())) {
        return Err(to_py(ImuError::invalid(format!("p[{i}] = {:?} is not finite", p[i]))));
    }
    let v = py.allow_threads(|| core_align::derive_velocity(t, p, half_window));
    out2(py, v)
}

/// Storage for `preintegrate`'s outputs, reused across calls: a fresh zeroed megabyte per call
/// (12k samples) cost about a fifth of the whole call in zeroing and page faults.
static PREINTEGRATE_POOL: LazyLock<BufferPool> = LazyLock::new(BufferPool::default);

#[pyfunction]
#[allow(clippy::type_complexity)]
fn preintegrate<'py>(
    py: Python<'py>,
    t_ns: PyReadonlyArray1<'py, i64>,
    gyro: PyReadonlyArray2<'py, f64>,
    acc: PyReadonlyArray2<'py, f64>,
) -> PyResult<(ArrD<'py>, ArrD<'py>, ArrD<'py>, ArrD<'py>)> {
    let (t, g, a) = (
        slice1(&t_ns, "t_ns")?,
        rows::<3>(&gyro, "gyro")?,
        rows::<3>(&acc, "acc")?,
    );
    let n = t.len();
    let arrays = pooled_arrays(py, &PREINTEGRATE_POOL, &[&[n, 4], &[n, 3], &[n, 3], &[n]], |parts| {
        let [dq, dv, dp, dt]: [&mut [f64]; 4] = parts
            .try_into()
            .map_err(|_| ImuError::invalid("internal: preintegration buffer has the wrong number of parts"))?;
        let out = PreintegratedMut {
            dq_wxyz: dq.as_chunks_mut::<4>().0,
            dv: dv.as_chunks_mut::<3>().0,
            dp: dp.as_chunks_mut::<3>().0,
            dt,
        };
        // Writes every row (row 0 included), as `pooled_arrays` requires.
        integrate::preintegrate_into(t, g, a, out)
    })?;
    let [dq, dv, dp, dt]: [ArrD<'py>; 4] = arrays.try_into().map_err(|_| {
        to_py(ImuError::invalid(
            "internal: preintegration arrays have the wrong number of parts",
        ))
    })?;
    Ok((dq, dv, dp, dt))
}

fn labels_dict(py: Python<'_>, l: Labels) -> PyResult<Bound<'_, PyDict>> {
    let (nw, nh) = (l.starts.len(), l.horizons.len());
    let d = PyDict::new(py);
    d.set_item(
        "starts",
        out1(py, l.starts.iter().map(|&s| s as u64).collect::<Vec<u64>>()),
    )?;
    d.set_item(
        "horizons",
        out1(py, l.horizons.iter().map(|&s| s as u64).collect::<Vec<u64>>()),
    )?;
    d.set_item("dq_wxyz", out3(py, l.dq_wxyz, nw, nh)?)?;
    d.set_item("dv", out3(py, l.dv, nw, nh)?)?;
    d.set_item("dp", out3(py, l.dp, nw, nh)?)?;
    d.set_item("dt", out2_flat(py, l.dt, nw, nh)?)?;
    Ok(d)
}

#[pyfunction]
#[allow(clippy::too_many_arguments)]
fn window_labels<'py>(
    py: Python<'py>,
    t_ns: PyReadonlyArray1<'py, i64>,
    p: PyReadonlyArray2<'py, f64>,
    v: PyReadonlyArray2<'py, f64>,
    q_wxyz: PyReadonlyArray2<'py, f64>,
    window: usize,
    stride: usize,
    fractions: Vec<f64>,
    gravity: f64,
) -> PyResult<Bound<'py, PyDict>> {
    // Labels need ground truth only: borrow it, and write into numpy's own output arrays.
    let gt = GroundTruthView {
        t_ns: slice1(&t_ns, "t_ns")?,
        p: rows::<3>(&p, "p")?,
        v: rows::<3>(&v, "v")?,
        q_wxyz: rows::<4>(&q_wxyz, "q_wxyz")?,
    };
    // The checks (and so the errors) of labels::window_labels, in its order.
    let (hs, starts) = labels::horizons(window, &fractions)
        .and_then(|hs| Ok((hs, labels::window_starts(gt.len(), window, stride)?)))
        .and_then(|x| gt.check().map(|()| x))
        .map_err(to_py)?;
    let (nw, nh) = (starts.len(), hs.len());
    let dq = zeros(py, [nw, nh, 4])?;
    let dv = zeros(py, [nw, nh, 3])?;
    let dp = zeros(py, [nw, nh, 3])?;
    let dt = zeros(py, [nw, nh])?;
    {
        let (mut dq_w, mut dv_w, mut dp_w, mut dt_w) = (dq.readwrite(), dv.readwrite(), dp.readwrite(), dt.readwrite());
        let out = LabelsMut {
            dq_wxyz: rows_mut::<4, _>(&mut dq_w)?,
            dv: rows_mut::<3, _>(&mut dv_w)?,
            dp: rows_mut::<3, _>(&mut dp_w)?,
            dt: flat_mut(&mut dt_w)?,
        };
        // No windows (a sequence shorter than one): nothing to compute, and `labels_into` would
        // reject horizons that no window asks for (see `labels::window_labels`).
        if !starts.is_empty() {
            py.allow_threads(|| labels::labels_into(gt, &starts, &hs, gravity, out))
                .map_err(to_py)?;
        }
    }
    let d = PyDict::new(py);
    d.set_item(
        "starts",
        out1(py, starts.iter().map(|&s| s as u64).collect::<Vec<u64>>()),
    )?;
    d.set_item("horizons", out1(py, hs.iter().map(|&s| s as u64).collect::<Vec<u64>>()))?;
    d.set_item("dq_wxyz", dq)?;
    d.set_item("dv", dv)?;
    d.set_item("dp", dp)?;
    d.set_item("dt", dt)?;
    Ok(d)
}

/// Sample indices from Python: a 1-d uint64 or int64 array, or a sequence of ints. Negative
/// values and values past usize are an `InvalidInputError` naming the argument and the entry,
/// so the core only ever sees what its own checks can judge.
#[derive(FromPyObject)]
enum Indices<'py> {
    Unsigned(PyReadonlyArray1<'py, u64>),
    Signed(PyReadonlyArray1<'py, i64>),
    /// Python ints up to ±2^127 (so 2^64 − 1 and beyond are judged here, not by pyo3).
    List(Vec<i128>),
}

impl Indices<'_> {
    fn to_usize(&self, name: &str) -> PyResult<Vec<usize>> {
        let bad = |i: usize, v: String| {
            to_py(ImuError::invalid(format!(
                "{name}[{i}] = {v} is not a sample index (a non-negative integer)"
            )))
        };
        fn convert<T: Copy + ToString>(v: &[T], bad: impl Fn(usize, String) -> PyErr) -> PyResult<Vec<usize>>
        where
            usize: TryFrom<T>,
        {
            v.iter()
                .enumerate()
                .map(|(i, &x)| usize::try_from(x).map_err(|_| bad(i, x.to_string())))
                .collect()
        }
        match self {
            Indices::Unsigned(a) => convert(slice1(a, name)?, bad),
            Indices::Signed(a) => convert(slice1(a, name)?, bad),
            Indices::List(v) => convert(v, bad),
        }
    }
}

#[pyfunction]
#[allow(clippy::too_many_arguments)]
fn offset_rotation_angles<'py>(
    py: Python<'py>,
    t_ns: PyReadonlyArray1<'py, i64>,
    gyro: PyReadonlyArray2<'py, f64>,
    starts: Indices<'py>,
    horizons: Indices<'py>,
    dq_ref: PyReadonlyArray2<'py, f64>,
    tau: f64,
    period_ns: f64,
) -> PyResult<Bound<'py, numpy::PyArray1<f64>>> {
    let (t, g, q) = (
        slice1(&t_ns, "t_ns")?,
        rows::<3>(&gyro, "gyro")?,
        rows::<4>(&dq_ref, "dq_ref")?,
    );
    let starts = starts.to_usize("starts")?;
    let horizons = horizons.to_usize("horizons")?;
    let a = py
        .allow_threads(|| offset::offset_rotation_angles(t, g, &starts, &horizons, q, tau, period_ns))
        .map_err(to_py)?;
    Ok(out1(py, a))
}

#[pyfunction]
fn integrate_windows<'py>(
    py: Python<'py>,
    t_ns: PyReadonlyArray1<'py, i64>,
    gyro: PyReadonlyArray2<'py, f64>,
    acc: PyReadonlyArray2<'py, f64>,
    starts: Indices<'py>,
    horizons: Indices<'py>,
) -> PyResult<Bound<'py, PyDict>> {
    let (t, g, a) = (
        slice1(&t_ns, "t_ns")?,
        rows::<3>(&gyro, "gyro")?,
        rows::<3>(&acc, "acc")?,
    );
    let starts = starts.to_usize("starts")?;
    let horizons = horizons.to_usize("horizons")?;
    let l = py
        .allow_threads(|| integrate::integrate_windows(t, g, a, &starts, &horizons))
        .map_err(to_py)?;
    labels_dict(py, l)
}

/// A C-contiguous (B, W, 3) float64 array as its B·W rows, with B and W.
fn windows3<'a>(a: &'a PyReadonlyArray3<'_, f64>, name: &str) -> PyResult<(usize, usize, &'a [Vec3])> {
    let shape = a.shape();
    let bad = |why: &str| to_py(ImuError::invalid(format!("{name} must be {why}, got shape {shape:?}")));
    if shape[2] != 3 {
        return Err(bad("a (B, W, 3) array"));
    }
    // `as_slice` also takes Fortran order, whose buffer is not rows of 3.
    let flat = a
        .as_slice()
        .ok()
        .filter(|_| a.is_c_contiguous())
        .ok_or_else(|| bad("C-contiguous (use numpy.ascontiguousarray)"))?;
    Ok((shape[0], shape[1], flat.as_chunks::<3>().0))
}

/// Two (B, W, 3) window arrays of one shape and their (B, W) dt, as flat rows: (B, W, x, y, dt).
#[allow(clippy::type_complexity)]
fn window_inputs<'a>(
    x: &'a PyReadonlyArray3<'_, f64>,
    x_name: &str,
    y: &'a PyReadonlyArray3<'_, f64>,
    y_name: &str,
    dt: &'a PyReadonlyArray2<'_, f64>,
) -> PyResult<(usize, usize, &'a [[f64; 3]], &'a [[f64; 3]], &'a [f64])> {
    let (b, w, xs) = windows3(x, x_name)?;
    let (_, _, ys) = windows3(y, y_name)?;
    let invalid = |msg: String| to_py(ImuError::invalid(msg));
    if y.shape() != x.shape() {
        return Err(invalid(format!(
            "{y_name} has shape {:?}, {x_name} {:?}: they must match",
            y.shape(),
            x.shape()
        )));
    }
    if dt.shape() != [b, w] {
        return Err(invalid(format!("dt has shape {:?}, expected ({b}, {w})", dt.shape())));
    }
    let d = dt
        .as_slice()
        .ok()
        .filter(|_| dt.is_c_contiguous())
        .ok_or_else(|| invalid("dt must be C-contiguous (use numpy.ascontiguousarray)".into()))?;
    Ok((b, w, xs, ys, d))
}

#[pyfunction]
fn rotation_window_sums<'py>(
    py: Python<'py>,
    gyro: PyReadonlyArray3<'py, f64>,
    acc_g: PyReadonlyArray3<'py, f64>,
    dt: PyReadonlyArray2<'py, f64>,
    theta: PyReadonlyArray1<'py, f64>,
    horizons: Indices<'py>,
    jacobian: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let (b, w, g, a, d) = window_inputs(&gyro, "gyro", &acc_g, "acc_g", &dt)?;
    let invalid = |msg: String| to_py(ImuError::invalid(msg));
    let th: &[f64; THETA_LEN] = slice1(&theta, "theta")?
        .try_into()
        .map_err(|_| invalid(format!("theta has {} entries, expected {THETA_LEN}", theta.len())))?;
    let hs = horizons.to_usize("horizons")?;
    let r = py
        .allow_threads(|| rotsums::rotation_window_sums(g, a, d, b, w, th, &hs, jacobian))
        .map_err(to_py)?;
    let nh = hs.len();
    let out = PyDict::new(py);
    out.set_item("q_wxyz", out3_flat(py, r.q_wxyz, b, nh, 4)?)?;
    let sums = r
        .sums
        .map(|s| Array4::from_shape_vec((b, nh, SUM_ROWS, SUM_COLS), s).map(|x| x.into_pyarray(py)))
        .transpose()
        .map_err(|e| invalid(e.to_string()))?;
    out.set_item("sums", sums)?;
    Ok(out)
}

#[pyfunction]
fn velocity_window_sums<'py>(
    py: Python<'py>,
    rates: PyReadonlyArray3<'py, f64>,
    acc: PyReadonlyArray3<'py, f64>,
    dt: PyReadonlyArray2<'py, f64>,
    horizons: Indices<'py>,
) -> PyResult<Bound<'py, PyArray4<f64>>> {
    let (b, w, r, a, d) = window_inputs(&rates, "rates", &acc, "acc", &dt)?;
    let invalid = |msg: String| to_py(ImuError::invalid(msg));
    let hs = horizons.to_usize("horizons")?;
    let s = py
        .allow_threads(|| rotsums::velocity_window_sums(r, a, d, b, w, &hs))
        .map_err(to_py)?;
    Array4::from_shape_vec((b, hs.len(), SUM_ROWS, VEL_COLS), s)
        .map(|x| x.into_pyarray(py))
        .map_err(|e| invalid(e.to_string()))
}

/// Covariances → (M, 9, 9), moving the buffer (each `Cov9` is row-major).
fn covariances_out(py: Python<'_>, covs: Vec<Cov9>) -> PyResult<Bound<'_, PyArray3<f64>>> {
    let m = covs.len();
    out3_flat(py, covs.into_flattened().into_flattened(), m, 9, 9)
}

/// The signature both covariance functions share: stamps, gyro, acc, variances and sample indices.
type CovarianceFn = fn(&[i64], &[Vec3], &[Vec3], &[Var6], &[usize]) -> crate::error::Result<Vec<Cov9>>;

/// Checks the arrays, runs ``f`` with the GIL released and returns (M, 9, 9).
fn covariances_py<'py>(
    py: Python<'py>,
    inputs: CovarianceInputs<'_, 'py>,
    index_name: &str,
    f: CovarianceFn,
) -> PyResult<Bound<'py, PyArray3<f64>>> {
    let (t_ns, gyro, acc, var, idx) = inputs;
    let (t, g, a, v) = (
        slice1(t_ns, "t_ns")?,
        rows::<3>(gyro, "gyro")?,
        rows::<3>(acc, "acc")?,
        rows::<6>(var, "var")?,
    );
    let is = idx.to_usize(index_name)?;
    let covs = py.allow_threads(|| f(t, g, a, v, &is)).map_err(to_py)?;
    covariances_out(py, covs)
}

type CovarianceInputs<'a, 'py> = (
    &'a PyReadonlyArray1<'py, i64>,
    &'a PyReadonlyArray2<'py, f64>,
    &'a PyReadonlyArray2<'py, f64>,
    &'a PyReadonlyArray2<'py, f64>,
    &'a Indices<'py>,
);

#[pyfunction]
fn increment_covariance<'py>(
    py: Python<'py>,
    t_ns: PyReadonlyArray1<'py, i64>,
    gyro: PyReadonlyArray2<'py, f64>,
    acc: PyReadonlyArray2<'py, f64>,
    var: PyReadonlyArray2<'py, f64>,
    horizons: Indices<'py>,
) -> PyResult<Bound<'py, PyArray3<f64>>> {
    let inputs = (&t_ns, &gyro, &acc, &var, &horizons);
    covariances_py(py, inputs, "horizons", covariance::increment_covariance)
}

#[pyfunction]
fn interval_covariances<'py>(
    py: Python<'py>,
    t_ns: PyReadonlyArray1<'py, i64>,
    gyro: PyReadonlyArray2<'py, f64>,
    acc: PyReadonlyArray2<'py, f64>,
    var: PyReadonlyArray2<'py, f64>,
    boundaries: Indices<'py>,
) -> PyResult<Bound<'py, PyArray3<f64>>> {
    let inputs = (&t_ns, &gyro, &acc, &var, &boundaries);
    covariances_py(py, inputs, "boundaries", covariance::interval_covariances)
}

/// Sequences held in Rust once, so each batch costs only the windows it draws.
#[pyclass(module = "imu_learn._imu_core", frozen)]
struct SequenceSet {
    seqs: Vec<Sequence>,
    /// Storage of returned batches, reused once Python has dropped them.
    pool: BufferPool,
}

type SeqTuple<'py> = (
    PyReadonlyArray1<'py, i64>,
    PyReadonlyArray2<'py, f64>,
    PyReadonlyArray2<'py, f64>,
    PyReadonlyArray2<'py, f64>,
    PyReadonlyArray2<'py, f64>,
    PyReadonlyArray2<'py, f64>,
);

fn batch_dict(py: Python<'_>, b: Batch, window: usize) -> PyResult<Bound<'_, PyDict>> {
    let nb = b.seq_index.len();
    let nh = b.horizons.len();
    let d = PyDict::new(py);
    d.set_item("imu", out3_flat(py, b.imu, nb, window, 6)?)?;
    d.set_item("dt", out2_flat(py, b.dt, nb, window)?)?;
    d.set_item("dq_wxyz", out3(py, b.dq_wxyz, nb, nh)?)?;
    d.set_item("dv", out3(py, b.dv, nb, nh)?)?;
    d.set_item("dp", out3(py, b.dp, nb, nh)?)?;
    d.set_item("label_dt", out2_flat(py, b.label_dt, nb, nh)?)?;
    d.set_item("bias", out3_flat(py, b.bias, nb, window, 6)?)?;
    d.set_item("seq_index", out1(py, b.seq_index))?;
    d.set_item("start", out1(py, b.start))?;
    d.set_item(
        "horizons",
        out1(py, b.horizons.iter().map(|&h| h as u64).collect::<Vec<u64>>()),
    )?;
    Ok(d)
}

#[pymethods]
impl SequenceSet {
    #[new]
    fn new(parts: Vec<SeqTuple<'_>>) -> PyResult<Self> {
        let mut seqs = Vec::with_capacity(parts.len());
        for (i, (t, g, a, p, v, q)) in parts.iter().enumerate() {
            let s = Sequence {
                t_ns: slice1(t, "t_ns")?.to_vec(),
                gyro: rows::<3>(g, "gyro")?.to_vec(),
                acc: rows::<3>(a, "acc")?.to_vec(),
                p: rows::<3>(p, "p")?.to_vec(),
                v: rows::<3>(v, "v")?.to_vec(),
                q_wxyz: rows::<4>(q, "q_wxyz")?.to_vec(),
            };
            labels::check_sequence(&s).map_err(|e| to_py(ImuError::invalid(format!("sequence {i}: {e}"))))?;
            seqs.push(s);
        }
        Ok(SequenceSet {
            seqs,
            pool: BufferPool::default(),
        })
    }

    fn __len__(&self) -> usize {
        self.seqs.len()
    }

    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (window, batch_size, fractions, gravity, seed, gyro_noise_density=0.0, acc_noise_density=0.0,
                        gyro_bias_max=0.0, acc_bias_max=0.0, gyro_bias_walk=0.0, acc_bias_walk=0.0))]
    fn make_batch<'py>(
        &self,
        py: Python<'py>,
        window: usize,
        batch_size: usize,
        fractions: Vec<f64>,
        gravity: f64,
        seed: u64,
        gyro_noise_density: f64,
        acc_noise_density: f64,
        gyro_bias_max: f64,
        acc_bias_max: f64,
        gyro_bias_walk: f64,
        acc_bias_walk: f64,
    ) -> PyResult<Bound<'py, PyDict>> {
        let cfg = BatchConfig {
            window,
            batch_size,
            fractions,
            gravity,
            augment: AugmentConfig {
                gyro_noise_density,
                acc_noise_density,
                gyro_bias_max,
                acc_bias_max,
                gyro_bias_walk,
                acc_bias_walk,
            },
        };
        let plan = BatchPlan::new(&self.seqs, &cfg).map_err(to_py)?;
        let (b, w, h) = (batch_size, window, plan.horizons.len());
        // `BatchPlan::new` bounded b × w; memory that still runs out is a MemoryError.
        let mut seq_index = try_zeroed::<u32>(b)?;
        let mut start = try_zeroed::<u64>(b)?;
        let (seqs, plan_ref, cfg_ref) = (&self.seqs, &plan, &cfg);
        let arrays = {
            let (si, st) = (&mut seq_index[..], &mut start[..]);
            pooled_arrays(
                py,
                &self.pool,
                &[
                    &[b, w, 6],
                    &[b, w],
                    &[b, h, 4],
                    &[b, h, 3],
                    &[b, h, 3],
                    &[b, h],
                    &[b, w, 6],
                ],
                move |parts| {
                    let [imu, dt, dq, dv, dp, label_dt, bias]: [&mut [f64]; 7] = parts
                        .try_into()
                        .map_err(|_| ImuError::invalid("internal: batch buffer has the wrong number of parts"))?;
                    let out = BatchMut {
                        imu,
                        dt,
                        dq_wxyz: dq.as_chunks_mut::<4>().0,
                        dv: dv.as_chunks_mut::<3>().0,
                        dp: dp.as_chunks_mut::<3>().0,
                        label_dt,
                        bias,
                        seq_index: si,
                        start: st,
                    };
                    // `fill` writes every element of every output (augment writes each bias row
                    // even when the bias is zero), as `pooled_arrays` requires.
                    plan_ref.fill(seqs, cfg_ref, seed, out)
                },
            )?
        };
        let [imu, dt, dq, dv, dp, label_dt, bias]: [Bound<'py, PyArrayDyn<f64>>; 7] =
            arrays.try_into().map_err(|_| {
                to_py(ImuError::invalid(
                    "internal: batch arrays have the wrong number of parts",
                ))
            })?;
        let d = PyDict::new(py);
        d.set_item("imu", imu)?;
        d.set_item("dt", dt)?;
        d.set_item("dq_wxyz", dq)?;
        d.set_item("dv", dv)?;
        d.set_item("dp", dp)?;
        d.set_item("label_dt", label_dt)?;
        d.set_item("bias", bias)?;
        d.set_item("seq_index", out1(py, seq_index))?;
        d.set_item("start", out1(py, start))?;
        d.set_item(
            "horizons",
            out1(py, plan.horizons.iter().map(|&h| h as u64).collect::<Vec<u64>>()),
        )?;
        Ok(d)
    }

    fn eval_windows<'py>(
        &self,
        py: Python<'py>,
        window: usize,
        stride: usize,
        fractions: Vec<f64>,
        gravity: f64,
    ) -> PyResult<Bound<'py, PyDict>> {
        let b = py
            .allow_threads(|| batch::eval_windows(&self.seqs, window, stride, &fractions, gravity))
            .map_err(to_py)?;
        batch_dict(py, b, window)
    }
}

#[pyfunction]
fn filtfilt_section<'py>(
    py: Python<'py>,
    x: PyReadonlyArray2<'py, f64>,
    sos: PyReadonlyArray1<'py, f64>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let (n, cols) = (x.shape()[0], x.shape()[1]);
    let xs = x.as_slice().map_err(|_| {
        to_py(ImuError::invalid(
            "x must be C-contiguous (use numpy.ascontiguousarray)",
        ))
    })?;
    let s = slice1(&sos, "sos")?;
    let section: &filter::Section = s
        .try_into()
        .map_err(|_| to_py(ImuError::invalid(format!("sos has {} entries, expected 6", s.len()))))?;
    let out = py
        .allow_threads(|| filter::filtfilt_section(xs, n, cols, section))
        .map_err(to_py)?;
    out2_flat(py, out, n, cols)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(filtfilt_section, m)?)?;
    m.add_function(wrap_pyfunction!(align, m)?)?;
    m.add_function(wrap_pyfunction!(derive_velocity, m)?)?;
    m.add_function(wrap_pyfunction!(preintegrate, m)?)?;
    m.add_function(wrap_pyfunction!(window_labels, m)?)?;
    m.add_function(wrap_pyfunction!(integrate_windows, m)?)?;
    m.add_function(wrap_pyfunction!(offset_rotation_angles, m)?)?;
    m.add_function(wrap_pyfunction!(rotation_window_sums, m)?)?;
    m.add_function(wrap_pyfunction!(velocity_window_sums, m)?)?;
    m.add_function(wrap_pyfunction!(increment_covariance, m)?)?;
    m.add_function(wrap_pyfunction!(interval_covariances, m)?)?;
    m.add_class::<SequenceSet>()?;
    Ok(())
}
