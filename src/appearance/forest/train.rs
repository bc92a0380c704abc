//! Training the forest: checking the samples, drawing each tree's bootstrap (or subsample)
//! from its own forked generator so the forest does not depend on the thread count, growing
//! trees with the histogram split search, and measuring the out-of-bag error.

use super::{Criterion, Forest, ForestParams, INTERNAL, Node, Samples, Tree, argmax};
use crate::appearance::features::FEATURE_COUNT;
use crate::rng::Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Why a forest cannot be trained on the samples given.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TrainError {
    #[error("no training samples")]
    NoSamples,
    #[error("a forest needs 2 to 255 classes, got {classes}")]
    ClassCount { classes: usize },
    #[error("sample class {class} is outside 0..{classes}")]
    ClassOutOfRange { class: usize, classes: usize },
    #[error("class {class} has no samples")]
    EmptyClass { class: usize },
    /// `allowed_features` names no feature that exists.
    #[error("no usable features selected")]
    NoFeatures,
}

/// What training measured.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainStats {
    pub samples: usize,
    pub samples_per_class: Vec<usize>,
    pub train_s: f64,
    /// Out-of-bag misclassification rate (unweighted); NaN without bootstrap.
    pub oob_error: f64,
    /// Out-of-bag error with classes weighed equally.
    pub oob_balanced_error: f64,
    pub nodes: usize,
}

impl Forest {
    /// Trains on `samples` with class indices in `0..classes`. Every class must have samples.
    pub fn train(
        samples: &Samples,
        classes: usize,
        params: &ForestParams,
    ) -> Result<(Forest, TrainStats), TrainError> {
        let started = std::time::Instant::now();
        let n = samples.len();
        if n == 0 {
            return Err(TrainError::NoSamples);
        }
        if !(2..=255).contains(&classes) {
            return Err(TrainError::ClassCount { classes });
        }
        let mut per_class = vec![0usize; classes];
        for &c in &samples.classes {
            let c = c as usize;
            if c >= classes {
                return Err(TrainError::ClassOutOfRange { class: c, classes });
            }
            per_class[c] += 1;
        }
        if let Some(c) = per_class.iter().position(|&k| k == 0) {
            return Err(TrainError::EmptyClass { class: c });
        }
        let class_weight: Vec<f64> = per_class
            .iter()
            .map(|&k| {
                if params.balance_classes {
                    n as f64 / (classes as f64 * k as f64)
                } else {
                    1.0
                }
            })
            .collect();
        let allowed: Vec<usize> = if params.allowed_features.is_empty() {
            (0..FEATURE_COUNT).collect()
        } else {
            params
                .allowed_features
                .iter()
                .copied()
                .filter(|&f| f < FEATURE_COUNT)
                .collect()
        };
        if allowed.is_empty() {
            return Err(TrainError::NoFeatures);
        }
        let mtry = if params.features_per_split == 0 {
            (allowed.len() as f64).sqrt().round() as usize
        } else {
            params.features_per_split.min(allowed.len())
        };
        let draws = if params.max_samples_per_tree == 0 {
            n
        } else {
            n.min(params.max_samples_per_tree)
        };
        // Feature-major copy: a split search reads one feature of many samples, and one
        // feature's column (n bytes) stays in cache where the rows (72·n bytes) do not
        // (training 1.6× faster on 94k samples).
        let mut columns = vec![0u8; FEATURE_COUNT * n];
        for (i, f) in samples.features.iter().enumerate() {
            for (j, &v) in f.iter().enumerate() {
                columns[j * n + i] = v;
            }
        }
        let trained: Vec<(Tree, Vec<u32>)> = (0..params.trees.max(1))
            .into_par_iter()
            .map(|t| {
                let mut rng = Rng::fork(params.seed, t as u64);
                let mut in_bag = vec![0u32; n];
                let indices: Vec<u32> = if params.bootstrap {
                    (0..draws).map(|_| rng.below(n) as u32).collect()
                } else if draws < n {
                    let mut all: Vec<u32> = (0..n as u32).collect();
                    for i in 0..draws {
                        let j = i + rng.below(n - i);
                        all.swap(i, j);
                    }
                    all.truncate(draws);
                    all
                } else {
                    (0..n as u32).collect()
                };
                for &i in &indices {
                    in_bag[i as usize] += 1;
                }
                let mut builder = TreeBuilder {
                    samples,
                    columns: &columns,
                    classes,
                    class_weight: &class_weight,
                    params,
                    allowed: &allowed,
                    mtry,
                    rng,
                    tree: Tree {
                        nodes: Vec::new(),
                        leaf_of: Vec::new(),
                        leaves: Vec::new(),
                        depth: 0,
                    },
                };
                // In increasing order, the split search's reads of each feature column go
                // forward through memory instead of jumping at random (the draws' order changes
                // nothing else: counts, partitions and the tree are the same). Forest bench, one
                // thread, alternating runs: training 0.32–0.39 s against 0.41–0.56 s unsorted.
                let mut idx = indices;
                idx.sort_unstable();
                builder.push_node();
                builder.grow(0, &mut idx, 0);
                (builder.tree, in_bag)
            })
            .collect();
        let (trees, bags): (Vec<Tree>, Vec<Vec<u32>>) = trained.into_iter().unzip();
        let forest = Forest::new(trees, classes, params.clone());
        // Out-of-bag: each sample voted on only by trees that did not see it.
        let (oob_error, oob_balanced_error) = if params.bootstrap || draws < n {
            let results: Vec<Option<(u8, bool)>> = (0..n)
                .into_par_iter()
                .map(|i| {
                    let mut acc = vec![0f32; classes];
                    let mut voters = 0;
                    for (tree, bag) in forest.trees.iter().zip(&bags) {
                        if bag[i] == 0 {
                            let leaf = tree.leaf(&samples.features[i]);
                            for (a, p) in acc.iter_mut().zip(&tree.leaves[leaf..leaf + classes]) {
                                *a += p;
                            }
                            voters += 1;
                        }
                    }
                    (voters > 0)
                        .then(|| (samples.classes[i], argmax(&acc) as u8 == samples.classes[i]))
                })
                .collect();
            let mut wrong = vec![0usize; classes];
            let mut seen = vec![0usize; classes];
            for (c, ok) in results.into_iter().flatten() {
                seen[c as usize] += 1;
                wrong[c as usize] += (!ok) as usize;
            }
            let total: usize = seen.iter().sum();
            let plain = if total > 0 {
                wrong.iter().sum::<usize>() as f64 / total as f64
            } else {
                f64::NAN
            };
            let rates: Vec<f64> = seen
                .iter()
                .zip(&wrong)
                .filter(|(s, _)| **s > 0)
                .map(|(s, w)| *w as f64 / *s as f64)
                .collect();
            (plain, rates.iter().sum::<f64>() / rates.len().max(1) as f64)
        } else {
            (f64::NAN, f64::NAN)
        };
        let stats = TrainStats {
            samples: n,
            samples_per_class: per_class,
            train_s: started.elapsed().as_secs_f64(),
            oob_error,
            oob_balanced_error,
            nodes: forest.trees.iter().map(|t| t.nodes.len()).sum(),
        };
        Ok((forest, stats))
    }
}

/// Grows one tree depth-first. `rng` is the tree's own forked generator: the features tried
/// at each split depend only on the seed and the tree's index, not on the other trees.
struct TreeBuilder<'a> {
    samples: &'a Samples,
    /// `samples`' features feature-major: feature f of sample i at `f * n + i`.
    columns: &'a [u8],
    classes: usize,
    class_weight: &'a [f64],
    params: &'a ForestParams,
    allowed: &'a [usize],
    mtry: usize,
    rng: Rng,
    tree: Tree,
}

impl TreeBuilder<'_> {
    fn impurity(&self, counts: &[f64], total: f64) -> f64 {
        if total <= 0.0 {
            return 0.0;
        }
        match self.params.criterion {
            Criterion::Gini => {
                1.0 - counts
                    .iter()
                    .map(|c| (c / total) * (c / total))
                    .sum::<f64>()
            }
            Criterion::Entropy => -counts
                .iter()
                .filter(|&&c| c > 0.0)
                .map(|c| (c / total) * (c / total).ln())
                .sum::<f64>(),
        }
    }

    fn make_leaf(&mut self, node: usize, idx: &[u32]) {
        let mut counts = vec![0f64; self.classes];
        for &i in idx {
            let c = self.samples.classes[i as usize] as usize;
            counts[c] += self.class_weight[c];
        }
        let total: f64 = counts.iter().sum::<f64>().max(1e-12);
        let start = self.tree.leaves.len() as u32;
        self.tree
            .leaves
            .extend(counts.iter().map(|c| (c / total) as f32));
        self.tree.nodes[node] = Node::leaf(node as u32);
        self.tree.leaf_of[node] = start;
    }

    fn push_node(&mut self) -> usize {
        self.tree.nodes.push(Node::leaf(0));
        self.tree.leaf_of.push(INTERNAL);
        self.tree.nodes.len() - 1
    }

    fn grow(&mut self, node: usize, idx: &mut [u32], depth: usize) {
        self.tree.depth = self.tree.depth.max(depth as u32);
        let k = self.classes;
        let min_leaf = self.params.min_samples_leaf.max(1);
        let first = self.samples.classes[idx[0] as usize];
        let pure = idx
            .iter()
            .all(|&i| self.samples.classes[i as usize] == first);
        if depth >= self.params.max_depth || idx.len() < 2 * min_leaf || pure {
            self.make_leaf(node, idx);
            return;
        }
        // Coarse bins on small nodes: the split search costs bins × classes per feature.
        let shift = if idx.len() > 1024 { 0 } else { 2 };
        let bins = 256 >> shift;
        let mut parent = vec![0f64; k];
        for &i in idx.iter() {
            let c = self.samples.classes[i as usize] as usize;
            parent[c] += self.class_weight[c];
        }
        let parent_total: f64 = parent.iter().sum();
        let parent_impurity = self.impurity(&parent, parent_total);
        let mut best: Option<(f64, usize, u8)> = None;
        let mut hist = vec![0f64; bins * k];
        let mut tally = vec![0u32; 2 * bins * k];
        let mut count = vec![0usize; bins];
        let mut tried = [false; FEATURE_COUNT];
        let mut attempts = 0;
        let mut left = vec![0f64; k];
        let mut right = vec![0f64; k];
        // As scikit-learn: past `mtry` features, keep drawing until one splits the node (with
        // 72 features, many are flat inside a small node; stopping there left the small tumour
        // class in leaves too early: tumour Dice 0.90 against scikit-learn's 0.96 on a widened
        // phantom).
        let improves = |best: &Option<(f64, usize, u8)>| {
            best.is_some_and(|(s, _, _)| s < parent_impurity - 1e-9)
        };
        while attempts < self.allowed.len() && (attempts < self.mtry.max(1) || !improves(&best)) {
            let f = self.allowed[self.rng.below(self.allowed.len())];
            if tried[f] {
                continue;
            }
            tried[f] = true;
            attempts += 1;
            // Counts in two interleaved tables (even and odd samples): neighbouring samples
            // often fall in one bin, and one table would chain every add on the last.
            tally.fill(0);
            let column = &self.columns[f * self.samples.len()..(f + 1) * self.samples.len()];
            let classes_of = &self.samples.classes;
            let bins_k = bins * k;
            let mut pairs = idx.chunks_exact(2);
            for p in pairs.by_ref() {
                let (i, j) = (p[0] as usize, p[1] as usize);
                tally[(column[i] >> shift) as usize * k + classes_of[i] as usize] += 1;
                tally[bins_k + (column[j] >> shift) as usize * k + classes_of[j] as usize] += 1;
            }
            for &i in pairs.remainder() {
                let i = i as usize;
                tally[(column[i] >> shift) as usize * k + classes_of[i] as usize] += 1;
            }
            for b in 0..bins {
                let mut n = 0;
                for c in 0..k {
                    let t = tally[b * k + c] + tally[bins_k + b * k + c];
                    hist[b * k + c] = t as f64 * self.class_weight[c];
                    n += t as usize;
                }
                count[b] = n;
            }
            left.fill(0.0);
            let mut left_n = 0usize;
            for b in 0..bins - 1 {
                for c in 0..k {
                    left[c] += hist[b * k + c];
                }
                left_n += count[b];
                if count[b] == 0 || left_n < min_leaf {
                    continue;
                }
                if idx.len() - left_n < min_leaf {
                    break;
                }
                let lt: f64 = left.iter().sum();
                for c in 0..k {
                    right[c] = parent[c] - left[c];
                }
                let rt = parent_total - lt;
                let score =
                    (lt * self.impurity(&left, lt) + rt * self.impurity(&right, rt)) / parent_total;
                if best.is_none_or(|(s, _, _)| score < s - 1e-12) {
                    // Threshold in u8 units: the top of bin b.
                    let threshold = (((b + 1) << shift) - 1) as u8;
                    best = Some((score, f, threshold));
                }
            }
        }
        let Some((_, feature, threshold)) = best.filter(|(s, _, _)| *s < parent_impurity - 1e-9)
        else {
            self.make_leaf(node, idx);
            return;
        };
        // Partition in place: ≤ threshold first.
        let mut split = 0;
        let column =
            &self.columns[feature * self.samples.len()..(feature + 1) * self.samples.len()];
        for j in 0..idx.len() {
            if column[idx[j] as usize] <= threshold {
                idx.swap(j, split);
                split += 1;
            }
        }
        if split == 0 || split == idx.len() {
            self.make_leaf(node, idx);
            return;
        }
        let child = self.push_node();
        self.push_node();
        self.tree.nodes[node] = Node::split(feature as u16, threshold, child as u32);
        let (l, r) = idx.split_at_mut(split);
        self.grow(child, l, depth + 1);
        self.grow(child + 1, r, depth + 1);
    }
}
