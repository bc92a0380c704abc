//! A multi-class random forest on u8 features, written for speed: histogram split search
//! (256 bins on large nodes, 64 on small ones), flat node arrays, trees trained in parallel
//! and deterministic for a given seed whatever the thread count, class-balanced sample weights
//! (strokes are unbalanced), bootstrap with out-of-bag error, and inference that walks the trees
//! tree-major over blocks of pixels so each tree stays in cache.

use super::features::{FEATURE_COUNT, FeatureVector};
use crate::rng::Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// How impurity is measured at a split.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum Criterion {
    #[default]
    Gini,
    Entropy,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ForestParams {
    /// N_b of the paper.
    pub trees: usize,
    pub max_depth: usize,
    pub min_samples_leaf: usize,
    /// Features tried per split; 0 = √(feature count).
    pub features_per_split: usize,
    pub bootstrap: bool,
    /// Cap on samples drawn per tree (0 = as many as there are).
    pub max_samples_per_tree: usize,
    pub criterion: Criterion,
    /// Weigh classes so each contributes equally. Off by default: on the phantoms it raised the
    /// small tumour class's false positives (mean tumour Dice 0.876 balanced vs 0.891 not, three
    /// scenes at noise 0.03); turn it on when strokes are far from the classes' true shares.
    pub balance_classes: bool,
    pub seed: u64,
    /// Features the splits may use (indices into the feature vector); empty = all.
    pub allowed_features: Vec<usize>,
}

impl Default for ForestParams {
    fn default() -> Self {
        Self {
            trees: 20,
            max_depth: 20,
            min_samples_leaf: 1,
            features_per_split: 0,
            bootstrap: true,
            max_samples_per_tree: 0,
            criterion: Criterion::Gini,
            balance_classes: false,
            seed: 0x00F0_4E57,
            allowed_features: Vec::new(),
        }
    }
}

/// Training samples: one feature vector and class index each.
#[derive(Debug, Clone, Default)]
pub struct Samples {
    pub features: Vec<FeatureVector>,
    pub classes: Vec<u8>,
}

impl Samples {
    pub fn len(&self) -> usize {
        self.classes.len()
    }

    pub fn is_empty(&self) -> bool {
        self.classes.is_empty()
    }

    pub fn push(&mut self, f: FeatureVector, class: u8) {
        self.features.push(f);
        self.classes.push(class);
    }
}

/// Marks an internal node in `Tree::leaf_of`.
const INTERNAL: u32 = u32::MAX;

/// One node: a split `x[feature] <= threshold` → `child`, else `child + 1`. A leaf is a node
/// that loops onto itself (feature 0, threshold 255, child = its own index), so a walk can take
/// a fixed number of steps without branching; its class probabilities start at `leaf_of[i]`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
struct Node {
    feature: u16,
    threshold: u8,
    child: u32,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct Tree {
    nodes: Vec<Node>,
    /// Per node: offset of its class probabilities in `leaves`, or [`INTERNAL`].
    leaf_of: Vec<u32>,
    leaves: Vec<f32>,
    /// Longest root-to-leaf path (steps).
    depth: u32,
}

/// A trained forest. Deserialising checks every tree (see `Tree::check`): a damaged session
/// file is refused, never walked.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "ForestData")]
pub struct Forest {
    trees: Vec<Tree>,
    classes: usize,
    pub params: ForestParams,
}

/// The serialised form of a [`Forest`], before its trees are checked.
#[derive(Deserialize)]
struct ForestData {
    trees: Vec<Tree>,
    classes: usize,
    params: ForestParams,
}

impl TryFrom<ForestData> for Forest {
    type Error = String;

    fn try_from(d: ForestData) -> Result<Self, String> {
        if d.trees.is_empty() || d.classes < 2 {
            return Err("forest has no trees or fewer than two classes".into());
        }
        for (i, t) in d.trees.iter().enumerate() {
            t.check(d.classes).map_err(|e| format!("tree {i}: {e}"))?;
        }
        Ok(Forest {
            trees: d.trees,
            classes: d.classes,
            params: d.params,
        })
    }
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
    pub fn classes(&self) -> usize {
        self.classes
    }

    pub fn tree_count(&self) -> usize {
        self.trees.len()
    }

    /// Trains on `samples` with class indices in `0..classes`. Every class must have samples.
    pub fn train(
        samples: &Samples,
        classes: usize,
        params: &ForestParams,
    ) -> Result<(Forest, TrainStats), String> {
        let started = std::time::Instant::now();
        let n = samples.len();
        if n == 0 {
            return Err("no training samples".into());
        }
        if !(2..=255).contains(&classes) {
            return Err(format!("a forest needs 2 to 255 classes, got {classes}"));
        }
        let mut per_class = vec![0usize; classes];
        for &c in &samples.classes {
            let c = c as usize;
            if c >= classes {
                return Err(format!("sample class {c} is outside 0..{classes}"));
            }
            per_class[c] += 1;
        }
        if let Some(c) = per_class.iter().position(|&k| k == 0) {
            return Err(format!("class {c} has no samples"));
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
            return Err("no usable features selected".into());
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
                let mut idx = indices;
                builder.push_node();
                builder.grow(0, &mut idx, 0);
                (builder.tree, in_bag)
            })
            .collect();
        let (trees, bags): (Vec<Tree>, Vec<Vec<u32>>) = trained.into_iter().unzip();
        let forest = Forest {
            trees,
            classes,
            params: params.clone(),
        };
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

    /// Class probabilities of one pixel (mean over trees), written to `out` (len = classes).
    pub fn predict(&self, f: &FeatureVector, out: &mut [f32]) {
        out.fill(0.0);
        for tree in &self.trees {
            let leaf = tree.leaf(f);
            for (o, p) in out.iter_mut().zip(&tree.leaves[leaf..leaf + self.classes]) {
                *o += p;
            }
        }
        let inv = 1.0 / self.trees.len() as f32;
        out.iter_mut().for_each(|o| *o *= inv);
    }

    /// Probabilities of many pixels: `classes` values per pixel, row after row.
    pub fn predict_many(&self, features: &[FeatureVector]) -> Vec<f32> {
        const BLOCK: usize = 1024;
        const LANES: usize = 16;
        let k = self.classes;
        let mut out = vec![0f32; features.len() * k];
        let inv = 1.0 / self.trees.len() as f32;
        out.par_chunks_mut(BLOCK * k)
            .zip(features.par_chunks(BLOCK))
            .for_each(|(o, fs)| {
                for tree in &self.trees {
                    let mut lanes = fs.chunks_exact(LANES);
                    for (g, group) in lanes.by_ref().enumerate() {
                        // 16 walks in lockstep: their dependent loads overlap.
                        let mut idx = [0u32; LANES];
                        let mut steps = 0;
                        while steps < tree.depth {
                            // Four steps between checks: most walks end well before the deepest.
                            for _ in 0..4 {
                                for l in 0..LANES {
                                    idx[l] = tree.step(idx[l], &group[l]);
                                }
                            }
                            steps += 4;
                            if idx.iter().all(|&i| tree.leaf_of[i as usize] != INTERNAL) {
                                break;
                            }
                        }
                        for (l, &i) in idx.iter().enumerate() {
                            let leaf = tree.leaf_of[i as usize] as usize;
                            let j = g * LANES + l;
                            for (a, p) in o[j * k..(j + 1) * k]
                                .iter_mut()
                                .zip(&tree.leaves[leaf..leaf + k])
                            {
                                *a += p;
                            }
                        }
                    }
                    let done = fs.len() - lanes.remainder().len();
                    for (j, f) in lanes.remainder().iter().enumerate() {
                        let leaf = tree.leaf(f);
                        let j = done + j;
                        for (a, p) in o[j * k..(j + 1) * k]
                            .iter_mut()
                            .zip(&tree.leaves[leaf..leaf + k])
                        {
                            *a += p;
                        }
                    }
                }
                o.iter_mut().for_each(|v| *v *= inv);
            });
        out
    }

    /// Longest path of each tree.
    pub fn depths(&self) -> Vec<u32> {
        self.trees.iter().map(|t| t.depth).collect()
    }
}

pub fn argmax(v: &[f32]) -> usize {
    let mut best = 0;
    for (i, &x) in v.iter().enumerate() {
        if x > v[best] {
            best = i;
        }
    }
    best
}

impl Tree {
    /// One step of a walk from node `i` (a leaf steps onto itself).
    #[inline(always)]
    fn step(&self, i: u32, f: &FeatureVector) -> u32 {
        // SAFETY: every tree is either built by `TreeBuilder` or deserialised through
        // `Tree::try_from(TreeData)`, which both guarantee that `i` (the root or a child index)
        // is below `nodes.len()`, that a split's `child + 1` is too, and that `feature` is
        // below FEATURE_COUNT (the length of `f`). This is the forest's hot loop: bounds checks
        // here cost a third of inference time.
        unsafe {
            let n = self.nodes.get_unchecked(i as usize);
            n.child + (*f.get_unchecked(n.feature as usize) > n.threshold) as u32
        }
    }

    /// Checks the invariants `step` relies on.
    fn check(&self, classes: usize) -> Result<(), String> {
        let n = self.nodes.len();
        if n == 0 || self.leaf_of.len() != n {
            return Err("tree has no nodes or a leaf table of the wrong size".into());
        }
        for (i, node) in self.nodes.iter().enumerate() {
            match self.leaf_of[i] {
                INTERNAL => {
                    if node.feature as usize >= FEATURE_COUNT || node.child as usize + 1 >= n {
                        return Err(format!(
                            "node {i} splits on a feature or child that does not exist"
                        ));
                    }
                }
                at => {
                    if node.child as usize != i
                        || node.threshold != u8::MAX
                        || at as usize + classes > self.leaves.len()
                    {
                        return Err(format!("leaf {i} is malformed"));
                    }
                }
            }
        }
        Ok(())
    }

    #[inline]
    fn leaf(&self, f: &FeatureVector) -> usize {
        let mut i = 0usize;
        loop {
            let at = self.leaf_of[i];
            if at != INTERNAL {
                return at as usize;
            }
            let node = self.nodes[i];
            i = node.child as usize + (f[node.feature as usize] > node.threshold) as usize;
        }
    }
}

struct TreeBuilder<'a> {
    samples: &'a Samples,
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
        self.tree.nodes[node] = Node {
            feature: 0,
            threshold: u8::MAX,
            child: node as u32,
        };
        self.tree.leaf_of[node] = start;
    }

    fn push_node(&mut self) -> usize {
        self.tree.nodes.push(Node {
            feature: 0,
            threshold: u8::MAX,
            child: 0,
        });
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
        let mut count = vec![0usize; bins];
        let mut tried = [false; FEATURE_COUNT];
        let mut attempts = 0;
        let mut left = vec![0f64; k];
        let mut right = vec![0f64; k];
        while attempts < self.mtry.max(1) {
            let f = self.allowed[self.rng.below(self.allowed.len())];
            if tried[f] {
                continue;
            }
            tried[f] = true;
            attempts += 1;
            hist.fill(0.0);
            count.fill(0);
            for &i in idx.iter() {
                let b = (self.samples.features[i as usize][f] >> shift) as usize;
                let c = self.samples.classes[i as usize] as usize;
                hist[b * k + c] += self.class_weight[c];
                count[b] += 1;
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
        for j in 0..idx.len() {
            if self.samples.features[idx[j] as usize][feature] <= threshold {
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
        self.tree.nodes[node] = Node {
            feature: feature as u16,
            threshold,
            child: child as u32,
        };
        let (l, r) = idx.split_at_mut(split);
        self.grow(child, l, depth + 1);
        self.grow(child + 1, r, depth + 1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Three classes separated by thresholds on two features, plus noise features.
    fn toy(n: usize, seed: u64) -> Samples {
        let mut rng = Rng::new(seed);
        let mut s = Samples::default();
        for _ in 0..n {
            let mut f = [0u8; FEATURE_COUNT];
            for v in f.iter_mut() {
                *v = rng.below(256) as u8;
            }
            let class = if f[3] < 80 {
                0
            } else if f[7] < 150 {
                1
            } else {
                2
            };
            s.push(f, class);
        }
        s
    }

    #[test]
    fn learns_axis_aligned_classes_deterministically() {
        let train = toy(6000, 1);
        let test = toy(2000, 2);
        let params = ForestParams {
            trees: 10,
            ..ForestParams::default()
        };
        let (forest, stats) = Forest::train(&train, 3, &params).unwrap();
        let probs = forest.predict_many(&test.features);
        let correct = test
            .classes
            .iter()
            .enumerate()
            .filter(|(i, c)| argmax(&probs[i * 3..i * 3 + 3]) == **c as usize)
            .count();
        let acc = correct as f64 / test.len() as f64;
        assert!(acc > 0.97, "held-out accuracy {acc}");
        assert!(stats.oob_error < 0.05, "oob {}", stats.oob_error);
        // Same seed, same forest; per-pixel prediction equals the block path.
        let (again, _) = Forest::train(&train, 3, &params).unwrap();
        assert_eq!(forest, again);
        let mut one = [0f32; 3];
        forest.predict(&test.features[5], &mut one);
        assert_eq!(&one[..], &probs[15..18]);
        assert!((one.iter().sum::<f32>() - 1.0).abs() < 1e-5);
    }

    #[test]
    fn balancing_weighs_classes_equally() {
        let mut s = toy(5000, 3);
        // Make class 2 rare: keep 1 in 20.
        let keep: Vec<usize> = (0..s.len())
            .filter(|&i| s.classes[i] != 2 || i % 20 == 0)
            .collect();
        s = Samples {
            features: keep.iter().map(|&i| s.features[i]).collect(),
            classes: keep.iter().map(|&i| s.classes[i]).collect(),
        };
        let shares: Vec<f64> = (0..3u8)
            .map(|c| s.classes.iter().filter(|&&k| k == c).count() as f64 / s.len() as f64)
            .collect();
        // A forest of root leaves predicts the (weighted) class shares of its samples.
        for balance in [true, false] {
            let params = ForestParams {
                trees: 1,
                max_depth: 0,
                bootstrap: false,
                balance_classes: balance,
                ..ForestParams::default()
            };
            let (f, _) = Forest::train(&s, 3, &params).unwrap();
            let mut p = [0f32; 3];
            f.predict(&s.features[0], &mut p);
            for c in 0..3 {
                let expect = if balance { 1.0 / 3.0 } else { shares[c] };
                assert!(
                    (p[c] as f64 - expect).abs() < 1e-5,
                    "balance {balance} class {c}: {} vs {expect}",
                    p[c]
                );
            }
        }
    }

    #[test]
    fn serialised_forests_round_trip_and_damaged_ones_are_refused() {
        let (forest, _) = Forest::train(
            &toy(500, 6),
            3,
            &ForestParams {
                trees: 3,
                ..ForestParams::default()
            },
        )
        .unwrap();
        let json = serde_json::to_string(&forest).unwrap();
        let back: Forest = serde_json::from_str(&json).unwrap();
        assert_eq!(back, forest);
        let mut v: serde_json::Value = serde_json::from_str(&json).unwrap();
        v["trees"][1]["nodes"][0]["child"] = 99999.into();
        let err = serde_json::from_value::<Forest>(v).unwrap_err().to_string();
        assert!(err.contains("tree 1"), "{err}");
        let mut v: serde_json::Value = serde_json::from_str(&json).unwrap();
        v["trees"][0]["nodes"][0]["feature"] = 200.into();
        assert!(serde_json::from_value::<Forest>(v).is_err());
    }

    #[test]
    fn refuses_bad_training_sets() {
        let s = toy(100, 5);
        assert!(Forest::train(&Samples::default(), 3, &ForestParams::default()).is_err());
        let only01 = Samples {
            features: s.features.clone(),
            classes: s.classes.iter().map(|c| c.min(&1)).copied().collect(),
        };
        assert!(
            Forest::train(&only01, 3, &ForestParams::default())
                .unwrap_err()
                .contains("class 2 has no samples")
        );
    }
}
