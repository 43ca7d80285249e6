//! Collision checks of a chain in a scene from Python (`stagerl.kinematics.CollisionChecker`):
//! the same checks as the environment's (`stagerl::sim::collision::ArmCollider`), over the same
//! geometry, for tools that plan or verify outside stagerl (OMPL's validity checker in
//! `scripts/bench/ompl_rrt_connect.py`, tests against PyBullet).

use numpy::{PyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use stagerl::sim::collision::{ArmCollider, Checks};

use crate::{bad_arg, guard};

/// A chain among obstacles, with the floor and self checks as asked.
#[pyclass(module = "stagerl._core", name = "CollisionChecker")]
pub struct CollisionChecker {
    chain: stagerl::robot::Chain,
    collider: ArmCollider,
    contacts: Vec<stagerl::sim::collision::Contact>,
}

impl CollisionChecker {
    pub(crate) fn build(
        chain: &stagerl::robot::Chain,
        obstacles: Option<&Bound<'_, PyAny>>,
        floor: bool,
        self_collision: bool,
    ) -> PyResult<Self> {
        let obstacles = crate::obstacles::obstacles_of(obstacles)?.unwrap_or_default();
        let mut collider = ArmCollider::new(chain, Checks { floor, self_collision });
        if collider.is_empty() {
            return Err(bad_arg(
                "robot",
                format!("`{}` -> `{}`", chain.base_link(), chain.tip_link()),
                "a chain with collision shapes: this one has none, so no check could find a contact",
            ));
        }
        collider.set_obstacles(&obstacles);
        Ok(CollisionChecker { chain: chain.clone(), collider, contacts: Vec::new() })
    }
}

#[pymethods]
impl CollisionChecker {
    /// For each row of `q` (N, dof): whether the arm is in contact, and the clearance (metres,
    /// the smallest signed distance over the checked pairs; negative: a penetration's depth;
    /// NaN only when no pair is checked at all, e.g. floor and self checks off and no obstacle).
    #[allow(clippy::type_complexity)]
    fn check<'py>(
        &mut self,
        py: Python<'py>,
        q: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<(Bound<'py, PyArray1<bool>>, Bound<'py, PyArray1<f64>>)> {
        let (n, dof) = (q.shape()[0], q.shape()[1]);
        if dof != self.chain.dof() {
            return Err(bad_arg("q.shape", format!("({n}, {dof})"), &format!("(N, {})", self.chain.dof())));
        }
        let q = crate::contiguous("q", &q)?;
        let (hit, clear) = guard("check", || {
            let (mut hit, mut clear) = (Vec::with_capacity(n), Vec::with_capacity(n));
            for i in 0..n {
                let qi = &q[dof * i..dof * (i + 1)];
                self.chain.try_fk(qi).map_err(|e| crate::kin::row_err(i, e))?;
                let c = self.collider.contacts(&self.chain, qi, &mut self.contacts);
                hit.push(!self.contacts.is_empty());
                clear.push(c.unwrap_or(f64::NAN));
            }
            Ok((hit, clear))
        })?;
        Ok((PyArray1::from_vec(py, hit), PyArray1::from_vec(py, clear)))
    }

    /// Whether the arm at one pose `q` (dof values) touches anything checked: the environment's
    /// per-step test (bounding spheres first, stops at the first contact), without the clearance.
    fn collides(&mut self, q: Vec<f64>) -> PyResult<bool> {
        if q.len() != self.chain.dof() {
            return Err(bad_arg(
                "q",
                format!("{} values", q.len()),
                &format!("{} values, one per joint", self.chain.dof()),
            ));
        }
        guard("collides", || {
            self.chain.try_fk(&q).map_err(|e| crate::kin::row_err(0, e))?;
            Ok(self.collider.check(&self.chain, &q).is_some())
        })
    }
}
