//! Contacts as unilateral rows of the Newton system (`StiffSettings::contact_rows`): a point on
//! a wall or a rod contact's plane keeps its inverse mass `w` across the wall in the banded
//! matrix, and its normal impulse is a multiplier of the solve, bounded below by zero.
//!
//! With pins (`pin.rs`), a point held on a plane has the projected inverse mass `w (I − n nᵀ)`
//! and its wall pushes or pulls whatever the linear step asks; which points the wall may hold
//! is decided between rounds (`contact.rs`, `rod_contact.rs`). On a stiff, finely resolved rod
//! pinned at consecutive points the linear step asks for normal impulses of alternating sign,
//! many times what the rod carries (the suture knot of `scenes/fishermans-knot-stiff.toml`:
//! `|n·g|/m` of 3–8 m at six neighbouring points after one iteration, pushing and pulling in
//! turn), and the iterate built on them does not converge. Here every Newton iteration solves
//! the linear step together with the contacts' complementarity:
//!
//! `[A B; Bᵀ D] [Δλ; Δp] = [r; s − q]`, `p + Δp ≥ 0`, `s ≥ 0`, `(p + Δp)·s = 0`,
//!
//! with `A` the banded matrix with the contact points' full normal mobility, `B = J K⁻¹ Nᵀ`
//! (column `c`: `w n` through the stretch–shear rows of the two elements of its point), `D` the
//! points' normal mobilities and `s` the gaps after the step. Eliminating `Δλ` (one banded
//! solve per contact column, at each factorisation) leaves the Schur complement
//! `S = D − Bᵀ A⁻¹ B`, symmetric positive definite and dense of the order of the contacts, and
//! an LCP in the total impulses `y = p + Δp`: `s = S y + c ≥ 0`, `y ≥ 0`, `yᵀ s = 0`, the
//! optimality conditions of `min ½ yᵀ S y + cᵀ y` over `y ≥ 0`, solved by a primal active set
//! (Lawson & Hanson's NNLS iteration with `S` in place of `AᵀA`) with `nalgebra`'s Cholesky.
//! Then `Δλ = A⁻¹ r − A⁻¹ B Δp`. Tangential motion (friction) is as for pins.
//!
//! A self-contact row (`Pinned::partner`, `rod_contact.rs`) holds a point's distance from the
//! closest point `x_m = (1 − t) x_j + t x_{j+1}` of another part of the same rod: its column of
//! `B` is `w n` through the elements of its point and `−(1 − t) w n`, `−t w n` through those of
//! `j` and `j + 1`, its gap is `n · (x − x_m)`, and `D` is the points' mobility along the
//! rows' normals, `D_rc = Σ_q w_q c_rq c_cq n_r · n_c` over the points rows `r` and `c` share
//! (no longer diagonal: two rows on one master segment share its points).

use super::Consts;
use super::direct::BlockTridiagonal;
use super::lanes::V3s;
use super::work::Work;
use cosserat_model::Vec3;
use nalgebra::{DMatrix, DVector};

/// A contact row's points with their weights along its normal (unused slots `usize::MAX`).
type RowPoints = [(usize, f64); 3];

/// The contact rows of a factorisation: which pins they are, `A⁻¹ B` and `S`.
#[derive(Clone, Debug, Default)]
pub(crate) struct ContactRows {
    /// Per row: the pinned point, and its index in `Work::pinned`.
    points: Vec<usize>,
    slots: Vec<usize>,
    /// Per row: `A⁻¹ B_c` (stretch–shear and bend–twist parts).
    cols: Vec<[V3s; 2]>,
    /// Per row: `B_c` as (element, entry) pairs: `w a` at element `i − 1` and `−w b` at
    /// element `i` for its point, and for a self-contact row (`Pinned::partner`) the same of
    /// its other side's two points, weighted by `−(1 − t)` and `−t`.
    b: Vec<Vec<(usize, Vec3<f64>)>>,
    /// Per row: its points with their weights (`(i, 1)`, and `(j, −(1 − t))`, `(j + 1, −t)`
    /// for a self-contact row) and its normal, for `D`: the points' mobility
    /// `D_rc = Σ_q w_q c_rq c_cq n_r · n_c` over the points rows `r` and `c` share.
    d: Vec<(RowPoints, Vec3<f64>)>,
    /// The Schur complement `D − Bᵀ A⁻¹ B`.
    s: DMatrix<f64>,
    /// Whether `cols` and `s` belong to the current factorisation.
    pub(crate) valid: bool,
}

impl ContactRows {
    /// The rows of the pins of `w` that are contacts of one plane (not a line, a crease or a
    /// point of zero mass), in `w.pinned`'s order.
    fn select(w: &Work, k: &Consts) -> (Vec<usize>, Vec<usize>) {
        w.pinned
            .iter()
            .enumerate()
            .filter(|(_, p)| w.is_row(p) && k.inv_mass[p.point] > 0.0)
            .map(|(s, p)| (p.point, s))
            .unzip()
    }

    /// Builds `A⁻¹ B` and `S` for the factorisation `factor` at the Jacobians of the last
    /// `Work::constraints`.
    pub(crate) fn build(&mut self, w: &Work, k: &Consts, factor: &BlockTridiagonal) {
        let (points, slots) = Self::select(w, k);
        self.points = points;
        self.slots = slots;
        self.valid = true;
        let m = self.points.len();
        let n = w.n;
        self.b.clear();
        self.d.clear();
        for (r, &s) in self.slots.iter().enumerate() {
            let p = &w.pinned[s];
            let i = p.point;
            // `B_c` of a point `q` pushed along the normal with weight `c`: its two elements.
            let mut entries: Vec<(usize, Vec3<f64>)> = Vec::with_capacity(6);
            let mut add = |q: usize, c: f64| {
                let wq = k.inv_mass[q] * c;
                if wq == 0.0 {
                    return;
                }
                let project = |j: usize| {
                    let il = k.cols.inv_l0[j];
                    Vec3::new(
                        w.dirs[0].get(j).dot(&p.normal),
                        w.dirs[1].get(j).dot(&p.normal),
                        w.dirs[2].get(j).dot(&p.normal),
                    ) * (il * wq)
                };
                for (j, e) in [(q.checked_sub(1), 1.0), ((q < n).then_some(q), -1.0)] {
                    if let Some(j) = j {
                        let v = project(j) * e;
                        match entries.iter_mut().find(|(a, _)| *a == j) {
                            Some((_, x)) => *x += v,
                            None => entries.push((j, v)),
                        }
                    }
                }
            };
            add(i, 1.0);
            if let Some((j, t)) = p.partner {
                add(j, -(1.0 - t));
                add(j + 1, -t);
            }
            let weights = match p.partner {
                Some((j, t)) => [(i, 1.0), (j, -(1.0 - t)), (j + 1, -t)],
                None => [(i, 1.0), (usize::MAX, 0.0), (usize::MAX, 0.0)],
            };
            self.d.push((weights, p.normal));
            if self.cols.len() <= r {
                self.cols.push([V3s::zeros(n), V3s::zeros(n)]);
            }
            let col = &mut self.cols[r];
            if col[0].x.len() != w.rhs[0].x.len() {
                *col = [V3s::zeros(n), V3s::zeros(n)];
            } else {
                col[0].fill_zero();
                col[1].fill_zero();
            }
            for &(j, v) in &entries {
                col[0].set(j, &v);
            }
            self.b.push(entries);
            factor.solve(col);
        }
        self.s = DMatrix::zeros(m, m);
        for r in 0..m {
            for c in 0..=r {
                let v = self.b_dot(r, &self.cols[c][0]);
                let d = self.mobility(k, r, c);
                self.s[(r, c)] = d - v;
            }
        }
        for r in 0..m {
            for c in r + 1..m {
                self.s[(r, c)] = self.s[(c, r)];
            }
        }
    }

    /// `D_rc`: the mobility of row `c`'s points along row `r`'s normal (see `d`).
    fn mobility(&self, k: &Consts, r: usize, c: usize) -> f64 {
        let ((a, na), (b, nb)) = (&self.d[r], &self.d[c]);
        let mut d = 0.0;
        for &(p, cp) in a.iter().filter(|q| q.0 != usize::MAX) {
            for &(q, cq) in b {
                if p == q {
                    d += k.inv_mass[p] * cp * cq;
                }
            }
        }
        if r == c { d } else { d * na.dot(nb) }
    }

    /// `B_rᵀ v` for a stretch–shear column `v`.
    fn b_dot(&self, r: usize, v: &V3s) -> f64 {
        self.b[r].iter().map(|(j, e)| e.dot(&v.get(*j))).sum()
    }

    /// Whether the rows were built for the pins `w` has now.
    pub(crate) fn fits(&self, w: &Work, k: &Consts) -> bool {
        self.valid && {
            let (points, slots) = Self::select(w, k);
            points == self.points && slots == self.slots
        }
    }

    /// After the banded solve of an iteration (`w.rhs` holds `A⁻¹ r`): solves the contacts' LCP, corrects `w.rhs` to `Δλ` and leaves each
    /// row's `Δp` in its pin.
    pub(crate) fn solve(&mut self, w: &mut Work) {
        let m = self.points.len();
        if m == 0 {
            return;
        }
        let mut c = DVector::zeros(m);
        let mut p = DVector::zeros(m);
        let u_normal = w.pin_normal_u();
        for r in 0..m {
            let pin = &mut w.pinned[self.slots[r]];
            let x = w.x.get(pin.point);
            // A self-contact row holds the distance from its other side's closest point.
            let rel = x - pin.partner.map_or(Vec3::zeros(), |q| lerp(&w.x, q));
            if pin.row_normal != pin.normal || pin.row_x != x {
                pin.row_offset = pin.normal.dot(&rel);
                pin.row_normal = pin.normal;
            }
            let gap = pin.normal.dot(&rel) - pin.row_offset;
            p[r] = pin.mult.max(0.0);
            c[r] = gap + u_normal[self.slots[r]] + self.b_dot(r, &w.rhs[0]);
        }
        // c of the LCP in the total impulses: s = S (y − p) + c_now.
        let c = &c - &self.s * &p;
        let y = nonnegative_qp(&self.s, &c, &p);
        for r in 0..m {
            let dp = y[r] - p[r];
            let pin = &mut w.pinned[self.slots[r]];
            pin.dmult = dp + (p[r] - pin.mult);
            if dp != 0.0 {
                let col = &self.cols[r];
                for part in 0..2 {
                    let (src, dst) = (&col[part], &mut w.rhs[part]);
                    for (d, s) in dst.x.iter_mut().zip(&src.x) {
                        *d -= dp * s;
                    }
                    for (d, s) in dst.y.iter_mut().zip(&src.y) {
                        *d -= dp * s;
                    }
                    for (d, s) in dst.z.iter_mut().zip(&src.z) {
                        *d -= dp * s;
                    }
                }
            }
        }
    }
}

/// `(1 − t) v_j + t v_{j+1}` for `(j, t)`.
fn lerp(v: &V3s, (j, t): (usize, f64)) -> Vec3<f64> {
    v.get(j) * (1.0 - t) + v.get(j + 1) * t
}

/// `argmin ½ yᵀ S y + cᵀ y` over `y ≥ 0` for a symmetric positive definite `S`, from the
/// feasible `start`: a primal active set (Lawson & Hanson's NNLS iteration), every entry free
/// at first. Each pass solves the unconstrained problem on the free set by Cholesky; a
/// solution with a negative entry is approached only as far as the first bound it meets, and
/// the entries that reach zero there on their way down join the bound set; otherwise the
/// bound entry whose gradient is most negative is freed. Stops at a KKT point or after
/// `4 m + 8` passes (the last feasible iterate).
fn nonnegative_qp(s: &DMatrix<f64>, c: &DVector<f64>, start: &DVector<f64>) -> DVector<f64> {
    let m = c.len();
    let mut y = start.map(|v| v.max(0.0));
    // Every entry free at first: where all contacts push (the common case) one Cholesky
    // solves it, and the first step back drops every entry that would pull at once.
    let mut free = vec![true; m];
    let scale = c.amax().max(1e-300);
    let tol = 1e-12 * scale;
    for _ in 0..4 * m + 8 {
        // Solve on the free set.
        let idx: Vec<usize> = (0..m).filter(|&i| free[i]).collect();
        let z = if idx.is_empty() {
            DVector::zeros(m)
        } else {
            let f = idx.len();
            let sub = DMatrix::from_fn(f, f, |a, b| s[(idx[a], idx[b])]);
            let rhs = DVector::from_fn(f, |a, _| -c[idx[a]]);
            let Some(ch) = sub.cholesky() else {
                return y;
            };
            let zf = ch.solve(&rhs);
            let mut z = DVector::zeros(m);
            for (a, &i) in idx.iter().enumerate() {
                z[i] = zf[a];
            }
            z
        };
        if idx.iter().all(|&i| z[i] > 0.0) {
            y = z;
            // Gradient on the bound set: s = S y + c must be ≥ 0 there.
            let g = s * &y + c;
            let worst = (0..m)
                .filter(|&i| !free[i])
                .min_by(|&a, &b| g[a].total_cmp(&g[b]));
            match worst {
                Some(j) if g[j] < -tol => {
                    free[j] = true;
                }
                _ => return y,
            }
        } else {
            // Step towards z as far as the first bound.
            let mut alpha = 1.0_f64;
            for &i in &idx {
                if z[i] <= 0.0 {
                    let d = y[i] - z[i];
                    if d > 0.0 {
                        alpha = alpha.min(y[i] / d);
                    }
                }
            }
            for &i in &idx {
                y[i] += alpha * (z[i] - y[i]);
                if z[i] <= 0.0 && y[i] <= 1e-14 * (1.0 + z[i].abs()) {
                    y[i] = 0.0;
                    free[i] = false;
                }
            }
        }
    }
    y
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stiff::contact::pin_impulse;
    use crate::stiff::direct::Assembled;
    use crate::stiff::pin::Pinned;
    use crate::stiff::work::tests::setup;

    /// One Newton iteration with points pressed onto their walls, as pins or as contact rows:
    /// the rows end complementary (every impulse at least zero, every gap closed or opening,
    /// never both), and where every impulse stays positive the iterate is the pinned one (the
    /// Schur complement of the rows is the projected matrix), to rounding. Of three
    /// neighbouring points pressed on one plane the middle one lifts off, which a pin cannot.
    /// The first iteration's linear step of `w` with its pins: constraints, preconditioner,
    /// right-hand side, assembly with the pins' blocks, and the factorisation, `w.rhs` solved
    /// in place.
    fn linear_step(w: &mut Work, k: &Consts) -> BlockTridiagonal {
        w.constraints(k);
        w.precondition(k, 1.0, true);
        w.rhs(k);
        let mut asm = Assembled::default();
        w.assemble(k, &mut asm);
        w.pin_blocks(k, &mut asm);
        let mut factor = BlockTridiagonal::default();
        factor.factor(&asm);
        factor.solve(&mut w.rhs);
        factor
    }

    #[test]
    fn pressed_contact_rows_step_as_pins() {
        let n = 9;
        let normal = Vec3::new(0.3, -0.5, 0.8).normalize();
        let step = |points: &[usize], rows: bool| {
            let (k, mut w) = setup(n);
            for i in 0..=n {
                w.x_pred.set(i, &w.x.get(i));
            }
            w.pinned = points
                .iter()
                .map(|&i| {
                    // Pushed into the wall by its target, further than the rod's perturbed
                    // constraints move it.
                    w.x_pred.set(i, &(w.x.get(i) - normal * 5e-2));
                    Pinned::on_wall(i, normal, false, 0.0, None)
                })
                .collect();
            w.contact_rows = rows;
            let factor = linear_step(&mut w, &k);
            if rows {
                let mut r = ContactRows::default();
                r.build(&w, &k, &factor);
                r.solve(&mut w);
            }
            let before: Vec<_> = (0..=n).map(|i| w.x.get(i)).collect();
            w.apply(&k, f64::INFINITY);
            let mut free = vec![];
            for p in w.pinned.iter().filter(|_| !rows) {
                assert_eq!(w.row_impulse(p), None, "pin {}", p.point);
            }
            if rows {
                let most = w.pinned.iter().fold(0.0_f64, |m, p| m.max(p.mult));
                for p in &w.pinned {
                    let gap = normal.dot(&(w.x.get(p.point) - before[p.point]));
                    assert!(p.mult >= 0.0 && gap > -1e-15, "point {}", p.point);
                    assert!(p.mult == 0.0 || gap.abs() < 1e-15, "point {}", p.point);
                    if p.mult == 0.0 {
                        free.push(p.point);
                    }
                    // The update reads a row's normal impulse as its multiplier (exactly zero
                    // when free), which the wall impulse `n · g` equals to rounding.
                    let wall = normal.dot(&pin_impulse(&w, &k, &w.lambda[0], p.point));
                    assert_eq!(w.row_impulse(p), Some(p.mult), "point {}", p.point);
                    assert!(
                        (wall - p.mult).abs() <= 1e-9 * most,
                        "point {}: {wall} vs {}",
                        p.point,
                        p.mult
                    );
                }
            }
            ((0..=n).map(|i| w.x.get(i)).collect::<Vec<_>>(), free)
        };
        let ((pins, _), (rows, free)) = (step(&[2, 5, 8], false), step(&[2, 5, 8], true));
        assert!(free.is_empty());
        for (i, (a, b)) in pins.iter().zip(&rows).enumerate() {
            assert!((a - b).norm() < 1e-12, "point {i}: {a} vs {b}");
        }
        let (_, free) = step(&[2, 3, 4], true);
        assert_eq!(free, [3]);
    }

    /// A self-contact row (`Pinned::partner`: point 2 against the segment of points 8 and 9
    /// of the same rod) pressed by both sides' targets: after one Newton iteration its impulse
    /// is positive, the distance between the point and the other side's closest point is
    /// what it was (the row closed), and the impulse acts on both sides, equal and opposite:
    /// the wall impulse `M (x − x̃) − Jᵀ λ` is `n p` at point 2, `−(1 − t) n p` and `−t n p`
    /// at points 8 and 9, and zero at every other point.
    #[test]
    fn a_self_contact_row_acts_on_both_sides() {
        let n = 12;
        let normal = Vec3::new(0.3, -0.5, 0.8).normalize();
        let (i, j, t) = (2, 8, 0.3);
        let (k, mut w) = setup(n);
        for q in 0..=n {
            w.x_pred.set(q, &w.x.get(q));
        }
        w.x_pred.set(i, &(w.x.get(i) - normal * 5e-2));
        for q in [j, j + 1] {
            w.x_pred.set(q, &(w.x.get(q) + normal * 3e-2));
        }
        let mut pin = Pinned::on_wall(i, normal, true, 0.0, None);
        pin.partner = Some((j, t));
        w.pinned = vec![pin];
        w.contact_rows = true;
        let distance = |w: &Work| normal.dot(&(w.x.get(i) - w.partner_x((j, t))));
        let before = distance(&w);
        let factor = linear_step(&mut w, &k);
        let mut rows = ContactRows::default();
        rows.build(&w, &k, &factor);
        rows.solve(&mut w);
        w.apply(&k, f64::INFINITY);
        let p = w.pinned[0].mult;
        assert!(p > 0.0, "impulse {p}");
        assert!(
            (distance(&w) - before).abs() < 1e-12,
            "distance {} vs {before}",
            distance(&w)
        );
        for q in 1..=n {
            let expected = match q {
                q if q == i => normal * p,
                q if q == j => -normal * ((1.0 - t) * p),
                q if q == j + 1 => -normal * (t * p),
                _ => Vec3::zeros(),
            };
            let got = pin_impulse(&w, &k, &w.lambda[0], q);
            assert!(
                (got - expected).norm() <= 1e-9 * p,
                "point {q}: {got} vs {expected}"
            );
        }
    }

    /// The active-set QP meets the LCP's conditions on a small random SPD problem, against
    /// every sign pattern tried by brute force.
    #[test]
    fn nonnegative_qp_solves_the_lcp() {
        let m = 6;
        let a = DMatrix::from_fn(m, m, |i, j| {
            ((i * 7 + j * 3) % 5) as f64 - 2.0 + if i == j { 3.0 } else { 0.0 }
        });
        let s = &a * a.transpose() + DMatrix::identity(m, m);
        let c = DVector::from_fn(m, |i, _| [1.0, -2.0, 0.5, -0.3, -4.0, 2.0][i]);
        let y = nonnegative_qp(&s, &c, &DVector::zeros(m));
        let g = &s * &y + &c;
        for i in 0..m {
            assert!(y[i] >= 0.0);
            assert!(g[i] >= -1e-10, "{g}");
            assert!((y[i] * g[i]).abs() < 1e-10);
        }
    }
}
