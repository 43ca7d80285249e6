//! A small dense quadratic program, solved exactly by Goldfarb and Idnani's dual active-set
//! method ("A numerically stable dual method for solving strictly convex quadratic programs",
//! Math. Programming 27, 1983), for the shield's projection
//!
//!   min_x 1/2 |x - c|^2   subject to   a_i . x >= b_i,  i = 1..m.
//!
//! The Hessian is the identity, so its Cholesky factor is too and the method's `J = L^-T Q` is
//! the orthogonal factor `Q` of the active constraints' normals, `N = Q [R; 0]`:
//! 1. start at the unconstrained minimum `x = c`, no active constraint;
//! 2. pick the most violated constraint `p` (`s_p = a_p . x - b_p < -tol`); none: `x` is optimal;
//! 3. `d = J^T a_p`; primal direction `z = J_2 d_2` (the part of `a_p` orthogonal to the active
//!    normals), dual direction `r = R^-1 d_1`;
//! 4. partial step `t1 = min_{r_j > 0} u_j / r_j` (the first active multiplier to reach 0, `k`),
//!    full step `t2 = -s_p / (z . a_p)` (`z != 0`);
//! 5. no step (`t1 = t2 = inf`): infeasible. Otherwise `x += t z`, `u_j -= t r_j`, `u_p += t`
//!    with `t = min(t1, t2)`; at `t2` add `p` (a Givens sweep makes `J^T a_p` zero below row
//!    `q`, giving `R`'s new column) and go to 2; at `t1` drop `k` (Givens rotations restore `R`'s
//!    triangle) and go to 3.
//!
//! The dual method keeps the multipliers non-negative and the objective rising, so it stops in
//! finitely many steps; an iteration cap (which no test reaches) answers "infeasible" rather
//! than loop. No allocation after [`Qp::new`].

/// Why no solution was returned.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum QpError {
    /// The constraints admit no point.
    Infeasible,
    /// The iteration cap was reached (treated as infeasible by the shield).
    IterationCap,
}

/// The solver with its workspace for `n` variables and up to `max_rows` constraints.
#[derive(Clone, Debug)]
pub struct Qp {
    n: usize,
    /// Row-major `m x n` normals and right-hand sides of the constraints of this problem.
    a: Vec<f64>,
    b: Vec<f64>,
    /// `J`, column-major `n x n`; `R`, column-major `n x n` upper triangle.
    j: Vec<f64>,
    r: Vec<f64>,
    active: Vec<usize>,
    u: Vec<f64>,
    d: Vec<f64>,
    z: Vec<f64>,
    rdir: Vec<f64>,
}

/// Tolerance on a constraint's violation (in its own units, rad/s here).
const TOL: f64 = 1e-10;

impl Qp {
    pub fn new(n: usize, max_rows: usize) -> Qp {
        Qp {
            n,
            a: Vec::with_capacity(max_rows * n),
            b: Vec::with_capacity(max_rows),
            j: vec![0.0; n * n],
            r: vec![0.0; n * n],
            active: Vec::with_capacity(n),
            u: Vec::with_capacity(n),
            d: vec![0.0; n],
            z: vec![0.0; n],
            rdir: vec![0.0; n],
        }
    }

    /// Forget the constraints.
    pub fn clear(&mut self) {
        self.a.clear();
        self.b.clear();
    }

    /// Add the constraint `row . x >= rhs` (`row.len() == n`).
    pub fn push(&mut self, row: &[f64], rhs: f64) {
        self.a.extend_from_slice(row);
        self.b.push(rhs);
    }

    /// Add `lo_i <= x_i <= hi_i` for every variable.
    pub fn push_bounds(&mut self, lo: &[f64], hi: &[f64]) {
        let n = self.n;
        for i in 0..n {
            for (sign, rhs) in [(1.0, lo[i]), (-1.0, -hi[i])] {
                let at = self.a.len();
                self.a.resize(at + n, 0.0);
                self.a[at + i] = sign;
                self.b.push(rhs);
            }
        }
    }

    /// The constraints added.
    pub fn rows(&self) -> usize {
        self.b.len()
    }

    /// `a_i . x - b_i`.
    pub fn slack(&self, i: usize, x: &[f64]) -> f64 {
        let row = &self.a[i * self.n..(i + 1) * self.n];
        row.iter().zip(x).map(|(a, x)| a * x).sum::<f64>() - self.b[i]
    }

    /// Solve for the point of the constraints nearest `c`, into `x` (steps 1-5).
    pub fn solve(&mut self, c: &[f64], x: &mut [f64]) -> Result<(), QpError> {
        let n = self.n;
        x.copy_from_slice(c);
        self.j.fill(0.0);
        for i in 0..n {
            self.j[i * n + i] = 1.0;
        }
        self.active.clear();
        self.u.clear();
        let cap = 10 * (self.rows() + n) + 10;
        let mut iterations = 0;
        loop {
            // Step 2: the most violated constraint.
            let mut p = None;
            let mut worst = -TOL;
            for i in 0..self.rows() {
                let s = self.slack(i, x);
                if s < worst && !self.active.contains(&i) {
                    worst = s;
                    p = Some(i);
                }
            }
            let Some(p) = p else { return Ok(()) };
            let mut u_p = 0.0;
            loop {
                iterations += 1;
                if iterations > cap {
                    return Err(QpError::IterationCap);
                }
                self.directions(p);
                let q = self.active.len();
                let (mut t1, mut k) = (f64::INFINITY, usize::MAX);
                for jj in 0..q {
                    if self.rdir[jj] > 1e-14 {
                        let t = self.u[jj] / self.rdir[jj];
                        if t < t1 {
                            (t1, k) = (t, jj);
                        }
                    }
                }
                let zz: f64 = self.z.iter().map(|v| v * v).sum();
                let za: f64 = (0..n).map(|i| self.z[i] * self.a[p * n + i]).sum();
                let s_p = self.slack(p, x);
                let t2 = if zz > 1e-24 && za > 1e-24 { -s_p / za } else { f64::INFINITY };
                let t = t1.min(t2);
                if !t.is_finite() {
                    return Err(QpError::Infeasible);
                }
                if t2.is_finite() {
                    for i in 0..n {
                        x[i] += t * self.z[i];
                    }
                }
                for jj in 0..q {
                    self.u[jj] -= t * self.rdir[jj];
                }
                u_p += t;
                if t2 <= t1 {
                    self.add(p);
                    self.u.push(u_p);
                    break;
                }
                self.drop(k);
            }
        }
    }

    /// Step 3: `d = J^T a_p`, `z = J_2 d_2`, `r = R^-1 d_1`.
    fn directions(&mut self, p: usize) {
        let (n, q) = (self.n, self.active.len());
        let row = &self.a[p * n..(p + 1) * n];
        for c in 0..n {
            self.d[c] = (0..n).map(|i| self.j[c * n + i] * row[i]).sum();
        }
        self.z.fill(0.0);
        for c in q..n {
            for i in 0..n {
                self.z[i] += self.d[c] * self.j[c * n + i];
            }
        }
        for i in (0..q).rev() {
            let mut v = self.d[i];
            for c in i + 1..q {
                v -= self.r[c * n + i] * self.rdir[c];
            }
            self.rdir[i] = v / self.r[i * n + i];
        }
    }

    /// Rotate columns `c1`, `c2` of `J` by the Givens pair `(cos, sin)`.
    fn rotate_j(&mut self, c1: usize, c2: usize, cos: f64, sin: f64) {
        let n = self.n;
        for i in 0..n {
            let (x, y) = (self.j[c1 * n + i], self.j[c2 * n + i]);
            self.j[c1 * n + i] = cos * x + sin * y;
            self.j[c2 * n + i] = -sin * x + cos * y;
        }
    }

    /// Step 5, adding constraint `p` (with `d = J^T a_p` from [`Qp::directions`]).
    fn add(&mut self, p: usize) {
        let (n, q) = (self.n, self.active.len());
        for c in (q + 1..n).rev() {
            let (x, y) = (self.d[c - 1], self.d[c]);
            if y == 0.0 {
                continue;
            }
            let h = x.hypot(y);
            let (cos, sin) = (x / h, y / h);
            self.d[c - 1] = h;
            self.d[c] = 0.0;
            self.rotate_j(c - 1, c, cos, sin);
        }
        for i in 0..=q {
            self.r[q * n + i] = self.d[i];
        }
        self.active.push(p);
    }

    /// Step 5, dropping active constraint number `k` (its place in the active set).
    fn drop(&mut self, k: usize) {
        let (n, q) = (self.n, self.active.len());
        // Shift R's columns after k left: an upper Hessenberg part remains in k..q-1.
        for c in k..q - 1 {
            for i in 0..n {
                self.r[c * n + i] = self.r[(c + 1) * n + i];
            }
        }
        for i in 0..n {
            self.r[(q - 1) * n + i] = 0.0;
        }
        for row in k..q - 1 {
            let (x, y) = (self.r[row * n + row], self.r[row * n + row + 1]);
            if y == 0.0 {
                continue;
            }
            let h = x.hypot(y);
            let (cos, sin) = (x / h, y / h);
            for c in row..q - 1 {
                let (a, b) = (self.r[c * n + row], self.r[c * n + row + 1]);
                self.r[c * n + row] = cos * a + sin * b;
                self.r[c * n + row + 1] = -sin * a + cos * b;
            }
            self.rotate_j(row, row + 1, cos, sin);
        }
        self.active.remove(k);
        self.u.remove(k);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A brute-force check of optimality: KKT with non-negative multipliers found by the
    /// solver is hard to get at; instead compare with a dense grid for 2 variables.
    #[test]
    fn matches_a_grid_search_in_two_dimensions() {
        let mut rng = crate::base::rng::Rng::new(7);
        for _ in 0..200 {
            let mut qp = Qp::new(2, 8);
            for _ in 0..3 {
                let row = [rng.uniform_range(-1.0, 1.0), rng.uniform_range(-1.0, 1.0)];
                qp.push(&row, rng.uniform_range(-1.0, 0.3));
            }
            qp.push_bounds(&[-1.0, -1.0], &[1.0, 1.0]);
            let c = [rng.uniform_range(-2.0, 2.0), rng.uniform_range(-2.0, 2.0)];
            let mut x = [0.0; 2];
            let solved = qp.solve(&c, &mut x);
            let (mut best, mut arg) = (f64::INFINITY, None);
            let steps = 400;
            for i in 0..=steps {
                for k in 0..=steps {
                    let y = [-1.0 + 2.0 * i as f64 / steps as f64, -1.0 + 2.0 * k as f64 / steps as f64];
                    if (0..qp.rows()).all(|r| qp.slack(r, &y) >= 0.0) {
                        let f = (y[0] - c[0]).powi(2) + (y[1] - c[1]).powi(2);
                        if f < best {
                            (best, arg) = (f, Some(y));
                        }
                    }
                }
            }
            match (solved, arg) {
                (Ok(()), Some(_)) => {
                    assert!((0..qp.rows()).all(|r| qp.slack(r, &x) >= -1e-9), "{x:?} infeasible");
                    let f = (x[0] - c[0]).powi(2) + (x[1] - c[1]).powi(2);
                    assert!(f <= best + 1e-9, "solver {f} > grid {best}");
                }
                (Err(_), None) => {}
                // A sliver of a feasible set the grid misses, or the reverse: rare; the
                // solver's answer must then still be feasible when it gives one.
                (Ok(()), None) => assert!((0..qp.rows()).all(|r| qp.slack(r, &x) >= -1e-9)),
                (Err(e), Some(y)) => panic!("{e:?} but {y:?} is feasible"),
            }
        }
    }

    #[test]
    fn an_unconstrained_point_is_returned_as_is_and_a_contradiction_is_infeasible() {
        let mut qp = Qp::new(3, 8);
        qp.push(&[1.0, 0.0, 0.0], -5.0);
        let mut x = [0.0; 3];
        qp.solve(&[0.5, -0.25, 2.0], &mut x).unwrap();
        assert_eq!(x, [0.5, -0.25, 2.0]);
        qp.push(&[-1.0, 0.0, 0.0], 6.0);
        assert!(qp.solve(&[0.5, -0.25, 2.0], &mut x).is_err());
    }

    #[test]
    fn projects_onto_a_half_space_and_a_corner() {
        let mut qp = Qp::new(3, 8);
        qp.push(&[0.0, 0.0, 2.0], 1.0);
        let mut x = [0.0; 3];
        qp.solve(&[1.0, 1.0, 0.0], &mut x).unwrap();
        assert!((x[2] - 0.5).abs() < 1e-12 && (x[0] - 1.0).abs() < 1e-12, "{x:?}");
        qp.push(&[1.0, 1.0, 0.0], 3.0);
        qp.solve(&[1.0, 1.0, 0.0], &mut x).unwrap();
        assert!((x[0] - 1.5).abs() < 1e-12 && (x[1] - 1.5).abs() < 1e-12 && (x[2] - 0.5).abs() < 1e-12);
    }
}
