//! PCA shape model of eq. 1: P = P̄ + U w. Built from a catalog of shapes with identical vertex
//! order (each sample may concatenate several structures: a joint model). Modes are unit
//! vectors over all coordinates, so a weight is in millimetres of displacement norm; each mode
//! keeps its standard deviation σ so weights can be limited to ±3σ.

use glam::DVec3;

/// Mean shape and principal modes of a catalog.
#[derive(Debug, Clone, PartialEq)]
pub struct PcaModel {
    pub mean: Vec<DVec3>,
    /// Unit-norm modes of variation, strongest first.
    pub modes: Vec<Vec<DVec3>>,
    /// Standard deviation of the catalog along each mode (mm).
    pub sigma_mm: Vec<f64>,
    /// Share of the catalog's variance the kept modes explain, in [0, 1].
    pub explained_share: f64,
    /// How many shapes the model was built from.
    pub sample_count: usize,
}

/// How many standard deviations a weight may reach.
pub const WEIGHT_LIMIT_SIGMA: f64 = 3.0;

impl PcaModel {
    /// Builds the model from `samples` (same length each). Keeps the fewest modes whose
    /// variance reaches `variance_share` of the total, at most `max_modes`.
    pub fn from_samples(
        samples: &[Vec<DVec3>],
        variance_share: f64,
        max_modes: usize,
    ) -> Result<Self, super::ShapeError> {
        let n = samples.len();
        let Some(first) = samples.first() else {
            return Err(super::ShapeError::EmptyCatalog);
        };
        let v = first.len();
        if let Some(i) = samples.iter().position(|s| s.len() != v) {
            return Err(super::ShapeError::SampleSize {
                index: i + 1,
                got: samples[i].len(),
                expected: v,
            });
        }
        let mean: Vec<DVec3> = (0..v)
            .map(|k| samples.iter().map(|s| s[k]).sum::<DVec3>() / n as f64)
            .collect();
        if n < 2 {
            return Ok(Self {
                mean,
                modes: Vec::new(),
                sigma_mm: Vec::new(),
                explained_share: 1.0,
                sample_count: n,
            });
        }
        // Eigen-decompose the small n×n Gram matrix of centred samples instead of the 3V×3V
        // covariance (the snapshot method): same non-zero spectrum, far cheaper.
        let centred: Vec<Vec<DVec3>> = samples
            .iter()
            .map(|s| s.iter().zip(&mean).map(|(p, m)| *p - *m).collect())
            .collect();
        let gram = nalgebra::DMatrix::from_fn(n, n, |i, j| {
            centred[i]
                .iter()
                .zip(&centred[j])
                .map(|(a, b)| a.dot(*b))
                .sum::<f64>()
        });
        let eig = nalgebra::SymmetricEigen::new(gram);
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
        let total: f64 = eig.eigenvalues.iter().map(|l| l.max(0.0)).sum();
        let mut modes = Vec::new();
        let mut sigma_mm = Vec::new();
        let mut kept = 0.0;
        if total > 1e-18 {
            for &k in &order {
                let lambda = eig.eigenvalues[k];
                if modes.len() >= max_modes
                    || kept / total >= variance_share
                    || lambda <= total * 1e-12
                {
                    break;
                }
                let q = eig.eigenvectors.column(k);
                let mut mode = vec![DVec3::ZERO; v];
                for (i, c) in centred.iter().enumerate() {
                    for (m, p) in mode.iter_mut().zip(c) {
                        *m += *p * q[i];
                    }
                }
                let norm = mode.iter().map(|m| m.length_squared()).sum::<f64>().sqrt();
                for m in &mut mode {
                    *m /= norm;
                }
                modes.push(mode);
                sigma_mm.push((lambda / (n - 1) as f64).sqrt());
                kept += lambda;
            }
        }
        Ok(Self {
            mean,
            modes,
            sigma_mm,
            explained_share: if total > 1e-18 { kept / total } else { 1.0 },
            sample_count: n,
        })
    }

    pub fn mode_count(&self) -> usize {
        self.modes.len()
    }

    /// Limits each weight to ±3σ of its mode.
    pub fn clamp_weights(&self, w: &mut [f64]) {
        for (x, s) in w.iter_mut().zip(&self.sigma_mm) {
            let lim = WEIGHT_LIMIT_SIGMA * s;
            *x = x.clamp(-lim, lim);
        }
    }

    /// The shape P̄ + U w (weights beyond the mode count are ignored, missing ones are zero).
    pub fn instance(&self, w: &[f64]) -> Vec<DVec3> {
        let mut out = self.mean.clone();
        for (mode, &wk) in self.modes.iter().zip(w) {
            if wk != 0.0 {
                for (o, m) in out.iter_mut().zip(mode) {
                    *o += *m * wk;
                }
            }
        }
        out
    }

    /// Least-squares weights of a shape: Uᵀ (P − P̄) (modes are orthonormal).
    pub fn project(&self, shape: &[DVec3]) -> Vec<f64> {
        self.modes
            .iter()
            .map(|mode| {
                mode.iter()
                    .zip(shape.iter().zip(&self.mean))
                    .map(|(m, (p, mu))| m.dot(*p - *mu))
                    .sum()
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// A catalog drawn from known orthonormal directions with known spreads.
    fn synthetic_catalog(
        rng: &mut Rng,
        v: usize,
        n: usize,
        sigmas: &[f64],
    ) -> (Vec<DVec3>, Vec<Vec<DVec3>>) {
        let mean: Vec<DVec3> = (0..v).map(|_| rng.unit_vector() * 30.0).collect();
        let mut dirs: Vec<Vec<DVec3>> = Vec::new();
        for _ in sigmas {
            let mut d: Vec<DVec3> = (0..v)
                .map(|_| DVec3::new(rng.normal(), rng.normal(), rng.normal()))
                .collect();
            for prev in &dirs {
                let dot: f64 = d.iter().zip(prev).map(|(a, b)| a.dot(*b)).sum();
                for (x, p) in d.iter_mut().zip(prev) {
                    *x -= *p * dot;
                }
            }
            let norm = d.iter().map(|x| x.length_squared()).sum::<f64>().sqrt();
            d.iter_mut().for_each(|x| *x /= norm);
            dirs.push(d);
        }
        let samples = (0..n)
            .map(|_| {
                let mut s = mean.clone();
                for (d, sg) in dirs.iter().zip(sigmas) {
                    let w = rng.normal() * sg;
                    for (x, dd) in s.iter_mut().zip(d) {
                        *x += *dd * w;
                    }
                }
                s
            })
            .collect();
        (mean, samples)
    }

    #[test]
    #[allow(clippy::needless_range_loop)] // mode index addresses three arrays
    fn matches_brute_force_covariance_eigendecomposition() {
        let mut rng = Rng::new(31);
        let (_, samples) = synthetic_catalog(&mut rng, 12, 25, &[6.0, 3.0, 1.0]);
        let model = PcaModel::from_samples(&samples, 1.0, 100).unwrap();
        // Brute force: the 36×36 covariance matrix and its eigenvectors.
        let d = 36;
        let n = samples.len();
        let flat = |s: &Vec<DVec3>| s.iter().flat_map(|p| [p.x, p.y, p.z]).collect::<Vec<f64>>();
        let rows: Vec<Vec<f64>> = samples.iter().map(flat).collect();
        let mean: Vec<f64> = (0..d)
            .map(|j| rows.iter().map(|r| r[j]).sum::<f64>() / n as f64)
            .collect();
        let cov = nalgebra::DMatrix::from_fn(d, d, |a, b| {
            rows.iter()
                .map(|r| (r[a] - mean[a]) * (r[b] - mean[b]))
                .sum::<f64>()
                / (n - 1) as f64
        });
        let eig = nalgebra::SymmetricEigen::new(cov);
        let mut order: Vec<usize> = (0..d).collect();
        order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
        for k in 0..3 {
            let lambda = eig.eigenvalues[order[k]];
            assert!(
                (model.sigma_mm[k] - lambda.sqrt()).abs() < 1e-8 * (1.0 + lambda.sqrt()),
                "sigma {k}"
            );
            let ev = eig.eigenvectors.column(order[k]);
            let mode = flat(&model.modes[k]);
            let dot: f64 = mode.iter().enumerate().map(|(i, m)| m * ev[i]).sum();
            assert!(
                (dot.abs() - 1.0).abs() < 1e-8,
                "mode {k} direction, |dot| = {}",
                dot.abs()
            );
        }
        // Every catalog member is reproduced from its projected weights.
        for s in &samples {
            let back = model.instance(&model.project(s));
            let err = back
                .iter()
                .zip(s)
                .map(|(a, b)| (*a - *b).length())
                .fold(0.0, f64::max);
            assert!(err < 1e-9, "reconstruction error {err}");
        }
    }

    #[test]
    fn variance_share_and_weight_limits() {
        let mut rng = Rng::new(32);
        let (_, samples) = synthetic_catalog(&mut rng, 50, 40, &[10.0, 5.0, 0.5]);
        let model = PcaModel::from_samples(&samples, 0.95, 10).unwrap();
        assert_eq!(
            model.mode_count(),
            2,
            "two modes explain ≥95% when the third has 0.2% of the variance"
        );
        assert!(model.explained_share >= 0.95 && model.explained_share < 1.0);
        let mut w = vec![1e3, -1e3];
        model.clamp_weights(&mut w);
        assert!((w[0] - 3.0 * model.sigma_mm[0]).abs() < 1e-12);
        assert!((w[1] + 3.0 * model.sigma_mm[1]).abs() < 1e-12);
        let one = PcaModel::from_samples(&samples[..1], 0.95, 10).unwrap();
        assert_eq!(one.mode_count(), 0);
        let mut bad = samples.clone();
        bad[3].pop();
        let err = PcaModel::from_samples(&bad, 0.95, 10).unwrap_err();
        assert_eq!(
            err,
            crate::shape::ShapeError::SampleSize {
                index: 4,
                got: samples[0].len() - 1,
                expected: samples[0].len()
            }
        );
        assert!(err.to_string().contains("shape 4"), "{err}");
    }
}
