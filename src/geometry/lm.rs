//! Levenberg–Marquardt for the small geometric refinements of this module (circle, ellipse,
//! homography, affine, fundamental matrix: 3–9 parameters).
//!
//! A problem is a cost Σ_i w_i r_i(θ)² over a state θ and a local parameterisation: `step`
//! moves the state by δ ∈ ℝᵖ (plain addition for most models; rotations for the rank-2 F). Each
//! iteration solves (JᵀJ + λ·(diag JᵀJ + 10⁻¹²·max diag))·δ = −Jᵀr and keeps δ only when the
//! cost drops (Marquardt's damping, λ ÷ 10 on success, × 10 on failure). The budget counts
//! evaluations (each trial step is one), so a refinement's cost is bounded. The returned state
//! is never worse than the start.

use super::linalg::solve;

/// A nonlinear least-squares problem, as [`minimise`] drives it.
pub trait LeastSquares {
    type State: Clone;
    /// Number of parameters p of a step.
    fn n_params(&self) -> usize;
    /// (cost Σ w r², JᵀJ as p × p row-major, Jᵀr as p values) at `state`; `None` where the
    /// model is undefined (e.g. a singular matrix).
    fn normal_equations(&self, state: &Self::State) -> Option<(f64, Vec<f64>, Vec<f64>)>;
    /// The state moved by `delta` (p values); `None` if that leaves the model's domain.
    fn step(&self, state: &Self::State, delta: &[f64]) -> Option<Self::State>;
}

/// The outcome of [`minimise`].
#[derive(Debug, Clone)]
pub struct Minimum<S> {
    pub state: S,
    pub cost: f64,
    /// Whether some step lowered the cost (else `state` is the start).
    pub improved: bool,
}

/// Runs Levenberg–Marquardt from `start` with at most `max_evals` evaluations of the normal
/// equations after the start's (a trial step costs one, accepted or not: the cost comes with
/// the Jacobian, so an accepted trial is not evaluated twice); stops early when an accepted
/// step lowers the cost by less than 1e-6 relative (statistically nothing: the cost of n noisy
/// points scatters by √(2/n)) (or it reaches 0). Never returns a state
/// with a higher cost than `start`. `None` when the start cannot be evaluated.
pub fn minimise<P: LeastSquares>(
    problem: &P,
    start: P::State,
    max_evals: usize,
) -> Option<Minimum<P::State>> {
    let p = problem.n_params();
    let (mut cost, mut jtj, mut jtr) = problem.normal_equations(&start)?;
    let mut state = start;
    let mut improved = false;
    let mut lambda = 1e-3;
    let mut budget = max_evals;
    'outer: while budget > 0 && cost > 0.0 {
        let max_diag = (0..p).map(|i| jtj[i * p + i]).fold(0.0f64, f64::max);
        if !(max_diag > 0.0) {
            break;
        }
        let minus_g: Vec<f64> = jtr.iter().map(|v| -v).collect();
        loop {
            if budget == 0 {
                break 'outer;
            }
            let mut a = jtj.clone();
            for i in 0..p {
                a[i * p + i] += lambda * (jtj[i * p + i] + 1e-12 * max_diag);
            }
            let trial = solve(&a, &minus_g, p)
                .and_then(|delta| problem.step(&state, &delta))
                .map(|s| {
                    budget -= 1;
                    let eq = problem.normal_equations(&s);
                    (s, eq)
                });
            match trial {
                Some((s, Some((c, a, g)))) if c < cost => {
                    let gain = (cost - c) / cost;
                    lambda = (lambda * 0.1).max(1e-12);
                    state = s;
                    cost = c;
                    jtj = a;
                    jtr = g;
                    improved = true;
                    if gain < 1e-6 {
                        break 'outer;
                    }
                    break;
                }
                _ => {
                    lambda *= 10.0;
                    if lambda > 1e12 {
                        break 'outer;
                    }
                }
            }
        }
    }
    Some(Minimum {
        state,
        cost,
        improved,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Fits y = a·exp(b·x) to exact data.
    struct Exp {
        xs: Vec<f64>,
        ys: Vec<f64>,
    }
    impl LeastSquares for Exp {
        type State = [f64; 2];
        fn n_params(&self) -> usize {
            2
        }
        fn normal_equations(&self, s: &[f64; 2]) -> Option<(f64, Vec<f64>, Vec<f64>)> {
            let (mut a, mut g, mut c) = (vec![0.0; 4], vec![0.0; 2], 0.0);
            for (x, y) in self.xs.iter().zip(&self.ys) {
                let e = (s[1] * x).exp();
                let r = s[0] * e - y;
                let j = [e, s[0] * x * e];
                c += r * r;
                for i in 0..2 {
                    g[i] += j[i] * r;
                    for k in 0..2 {
                        a[i * 2 + k] += j[i] * j[k];
                    }
                }
            }
            Some((c, a, g))
        }
        fn step(&self, s: &[f64; 2], d: &[f64]) -> Option<[f64; 2]> {
            Some([s[0] + d[0], s[1] + d[1]])
        }
    }

    #[test]
    fn converges_on_a_small_nonlinear_problem() {
        let xs: Vec<f64> = (0..20).map(|i| i as f64 * 0.1).collect();
        let ys: Vec<f64> = xs.iter().map(|x| 2.0 * (-1.3 * x).exp()).collect();
        let p = Exp { xs, ys };
        let m = minimise(&p, [1.0, 0.0], 50).unwrap();
        let s = m.state;
        assert!(m.improved && m.cost < 1e-12);
        assert!(
            (s[0] - 2.0).abs() < 1e-6 && (s[1] + 1.3).abs() < 1e-6,
            "{s:?}"
        );
    }
}
