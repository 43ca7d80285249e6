//! Batched kinematics of any URDF chain (`stagerl.kinematics.Chain`).

use numpy::{PyArray1, PyArray2, PyArray3, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;

use crate::{bad_arg, contiguous, guard, to_py};

/// A serial chain loaded from `"ur5"`, `"panda"` or a URDF file (see `stagerl::robot::Chain`).
#[pyclass(module = "stagerl._core", name = "Chain")]
pub struct Chain {
    chain: stagerl::robot::Chain,
}

type Arr2<'py> = Bound<'py, PyArray2<f64>>;

impl Chain {
    /// The rows of `q` after checking its shape and contiguity.
    fn rows<'a>(&self, q: &'a PyReadonlyArray2<'_, f64>) -> PyResult<(usize, &'a [f64])> {
        let (n, c, dof) = (q.shape()[0], q.shape()[1], self.chain.dof());
        if c != dof {
            return Err(bad_arg(
                "q.shape",
                format!("({n}, {c})"),
                &format!(
                    "(N, {dof}): one value per joint of `{}` -> `{}`",
                    self.chain.base_link(),
                    self.chain.tip_link()
                ),
            ));
        }
        let s = contiguous("q", q)?;
        Ok((n, s))
    }
}

/// `rows x 3` positions and `rows x 4` quaternions as numpy arrays.
fn pose_arrays<'py>(
    py: Python<'py>,
    n: usize,
    p: Vec<f64>,
    quat: Vec<f64>,
) -> PyResult<(Arr2<'py>, Arr2<'py>)> {
    Ok((PyArray1::from_vec(py, p).reshape([n, 3])?, PyArray1::from_vec(py, quat).reshape([n, 4])?))
}

#[pymethods]
impl Chain {
    #[new]
    #[pyo3(signature = (robot="ur5", tip=None))]
    fn new(robot: &str, tip: Option<&str>) -> PyResult<Self> {
        guard("Chain", || Ok(Chain { chain: stagerl::robot::Chain::load(robot, tip).map_err(to_py)? }))
    }

    #[getter]
    fn dof(&self) -> usize {
        self.chain.dof()
    }
    #[getter]
    fn joint_names(&self) -> Vec<String> {
        self.chain.joints().iter().map(|j| j.name.clone()).collect()
    }
    #[getter]
    fn base_link(&self) -> String {
        self.chain.base_link().to_string()
    }
    #[getter]
    fn tip_link(&self) -> String {
        self.chain.tip_link().to_string()
    }
    #[getter]
    fn lower_limits(&self) -> Vec<f64> {
        self.chain.lower_limits().to_vec()
    }
    #[getter]
    fn upper_limits(&self) -> Vec<f64> {
        self.chain.upper_limits().to_vec()
    }
    #[getter]
    fn velocity_limits(&self) -> Vec<f64> {
        self.chain.velocity_limits().to_vec()
    }

    /// A collision checker of this chain among `obstacles` (a list of dicts in
    /// `[[task.obstacles]]`'s schema), with the floor and self checks as asked.
    #[pyo3(signature = (obstacles=None, floor=true, self_collision=true))]
    fn checker(
        &self,
        obstacles: Option<&Bound<'_, PyAny>>,
        floor: bool,
        self_collision: bool,
    ) -> PyResult<crate::checker::CollisionChecker> {
        guard("checker", || {
            crate::checker::CollisionChecker::build(&self.chain, obstacles, floor, self_collision)
        })
    }

    /// Tip positions (N, 3) in metres and orientations (N, 4) as (x, y, z, w), w >= 0.
    fn fk<'py>(&self, py: Python<'py>, q: PyReadonlyArray2<'py, f64>) -> PyResult<(Arr2<'py>, Arr2<'py>)> {
        let (n, q) = self.rows(&q)?;
        let dof = self.chain.dof();
        let (p, quat) = guard("fk", || {
            let (mut p, mut quat) = (Vec::with_capacity(3 * n), Vec::with_capacity(4 * n));
            for i in 0..n {
                let pose = self.chain.try_fk(&q[dof * i..dof * (i + 1)]).map_err(|e| row_err(i, e))?;
                p.extend(pose.position.iter());
                quat.extend(pose.quaternion_xyzw());
            }
            Ok((p, quat))
        })?;
        pose_arrays(py, n, p, quat)
    }

    /// Geometric Jacobians (N, 6, dof) (rows vx, vy, vz, wx, wy, wz in the base frame), with the
    /// tip positions (N, 3) and orientations (N, 4).
    #[allow(clippy::type_complexity)]
    fn jacobian<'py>(
        &self,
        py: Python<'py>,
        q: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<(Bound<'py, PyArray3<f64>>, Arr2<'py>, Arr2<'py>)> {
        let (n, q) = self.rows(&q)?;
        let dof = self.chain.dof();
        let (jac, p, quat) = guard("jacobian", || {
            let mut jac = vec![0.0; 6 * dof * n];
            let (mut p, mut quat) = (Vec::with_capacity(3 * n), Vec::with_capacity(4 * n));
            for i in 0..n {
                let qi = &q[dof * i..dof * (i + 1)];
                // try_fk checks the row (length, finite values, overflow) before the Jacobian.
                self.chain.try_fk(qi).map_err(|e| row_err(i, e))?;
                let pose = self.chain.jacobian(qi, &mut jac[6 * dof * i..6 * dof * (i + 1)]);
                p.extend(pose.position.iter());
                quat.extend(pose.quaternion_xyzw());
            }
            Ok((jac, p, quat))
        })?;
        let jac = PyArray1::from_vec(py, jac).reshape([n, 6, dof])?;
        let (p, quat) = pose_arrays(py, n, p, quat)?;
        Ok((jac, p, quat))
    }
}

pub(crate) fn row_err(i: usize, e: stagerl::Error) -> PyErr {
    pyo3::exceptions::PyValueError::new_err(format!("q row {i}: {e}"))
}
