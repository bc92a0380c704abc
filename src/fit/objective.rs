//! The objective of one frame (eq. 12) as the optimiser sees it: a sum of image terms (the
//! correspondence lines of eq. 4, the stereo depth term) and priors (pose damping, strain,
//! shape, camera). Each part gives its energy at a state and its Gauss–Newton normal
//! equations for a parameter block; the optimiser only sums them, damps, solves, and accepts a
//! step when the same total energy falls (`optimizer::step`).

use super::state::{Block, FitState};
use glam::DVec3;
use nalgebra::{DMatrix, DVector};

/// Gauss–Newton normal equations H δ = b of one parameter block, where b = −∇E in the
/// Gauss–Newton approximation. Terms fill the upper triangle of `h` (column ≥ row); the
/// optimiser mirrors it before the priors add their diagonals.
#[derive(Debug, Clone, PartialEq)]
pub struct NormalEquations {
    pub h: DMatrix<f64>,
    pub b: DVector<f64>,
}

impl NormalEquations {
    pub fn zeros(n: usize) -> Self {
        Self {
            h: DMatrix::zeros(n, n),
            b: DVector::zeros(n),
        }
    }

    pub fn size(&self) -> usize {
        self.b.len()
    }

    /// Copies the upper triangle of `h` into the lower.
    pub fn symmetrise(&mut self) {
        let n = self.size();
        for r in 0..n {
            for q in 0..r {
                self.h[(r, q)] = self.h[(q, r)];
            }
        }
    }
}

/// An image term of the energy, fixed for the duration of one step (its lines or matches
/// measured at the step's start): smooth in the state, with an analytic gradient that the
/// tests check against central differences.
pub trait ImageTerm {
    /// The term's energy at `state`; `deformed` is the shape instance of `state.shape`.
    fn energy(&self, state: &FitState, deformed: &[Vec<DVec3>]) -> f64;
    /// ∂E/∂ξ for the parameters of `block`, analytic.
    fn gradient(&self, state: &FitState, deformed: &[Vec<DVec3>], block: Block) -> Vec<f64>;
    /// Adds the term's Gauss–Newton normal equations for `block` to `eq` (upper triangle).
    fn add_normal_equations(
        &self,
        state: &FitState,
        deformed: &[Vec<DVec3>],
        block: Block,
        eq: &mut NormalEquations,
    );
}

/// A quadratic prior on one block's parameters, with its precisions fixed when it is made (at
/// the start of a step), so that the energy it adds to the step's objective is the one whose
/// curvature it adds to the normal equations.
pub trait Prior {
    /// 0.5 Σ λ_k r_k(state)², in the units of the image terms' energy.
    fn energy(&self, state: &FitState) -> f64;
    /// Adds λ_k to the diagonal of `eq.h` and −λ_k r_k(state) to `eq.b` (the Gauss–Newton
    /// gradient: ∂r_k/∂ξ_k = 1 in the block's own increments).
    fn add_normal_equations(&self, state: &FitState, eq: &mut NormalEquations);
}
