//! A multi-class random forest on u8 features, written for speed: histogram split search
//! (256 bins on large nodes, 64 on small ones), flat node arrays, trees trained in parallel
//! and deterministic for a given seed whatever the thread count, class-balanced sample weights
//! (strokes are unbalanced), bootstrap with out-of-bag error, and inference that walks the trees
//! tree-major over blocks of pixels so each tree stays in cache, 8 walks in lockstep, each
//! ending on its leaf's probabilities stored by node and padded to 4 (one vector add) — or,
//! where the CPU has AVX2 or AVX-512 and neighbouring pixels share their paths, 64 pixels at
//! once by masks (`masks`).

mod masks;
mod train;

pub use train::{TrainError, TrainStats};

use super::features::{FEATURE_COUNT, FeatureVector};
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

impl Node {
    fn split(feature: u16, threshold: u8, child: u32) -> Self {
        Self {
            feature,
            threshold,
            child,
        }
    }

    /// A leaf at index `at` (it steps onto itself).
    fn leaf(at: u32) -> Self {
        Self::split(0, u8::MAX, at)
    }
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
    /// Per tree, per node, the class probabilities of the leaf the node is (zeros for a split)
    /// in `classes.div_ceil(4)` groups of 4: derived from `trees` (not serialised), so a walk
    /// that ends on node `i` adds its group(s) with no second lookup and no loop over classes.
    #[serde(skip)]
    by_node: Vec<Vec<[f32; 4]>>,
    /// Per tree, its layout for the masks (`masks`), where this CPU takes them (`masks_isa`;
    /// empty otherwise): derived from `trees`, not serialised.
    #[serde(skip)]
    masks: Vec<masks::MaskTree>,
    #[serde(skip)]
    masks_isa: Option<masks::Isa>,
}

/// The serialised form of a [`Forest`], before its trees are checked.
#[derive(Deserialize)]
struct ForestData {
    trees: Vec<Tree>,
    classes: usize,
    params: ForestParams,
}

/// Why a serialised forest is refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ForestDataError {
    #[error("forest has no trees or fewer than two classes")]
    Empty,
    #[error("tree {index}: {source}")]
    Tree { index: usize, source: TreeError },
}

/// A tree that breaks an invariant the walk relies on (see `Tree::check`); `node` indexes
/// the tree's flat node array.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TreeError {
    #[error("tree has no nodes or a leaf table of the wrong size")]
    Shape,
    #[error("node {node} splits on a feature or child that does not exist")]
    Split { node: usize },
    #[error("leaf {node} is malformed")]
    Leaf { node: usize },
    #[error("a path is longer than the tree's depth")]
    Depth,
    #[error("node {node} is a child of two splits")]
    Shared { node: usize },
}

impl TryFrom<ForestData> for Forest {
    type Error = ForestDataError;

    fn try_from(d: ForestData) -> Result<Self, ForestDataError> {
        if d.trees.is_empty() || d.classes < 2 {
            return Err(ForestDataError::Empty);
        }
        for (index, t) in d.trees.iter().enumerate() {
            t.check(d.classes)
                .map_err(|source| ForestDataError::Tree { index, source })?;
        }
        Ok(Forest::new(d.trees, d.classes, d.params))
    }
}

impl Forest {
    /// A forest of checked or freshly built trees.
    fn new(trees: Vec<Tree>, classes: usize, params: ForestParams) -> Self {
        let groups = classes.div_ceil(4);
        let by_node = trees
            .iter()
            .map(|t| {
                let mut table = vec![[0f32; 4]; t.nodes.len() * groups];
                for (i, &at) in t.leaf_of.iter().enumerate() {
                    if at != INTERNAL {
                        let probs = &t.leaves[at as usize..at as usize + classes];
                        for (c, &p) in probs.iter().enumerate() {
                            table[i * groups + c / 4][c % 4] = p;
                        }
                    }
                }
                table
            })
            .collect();
        let masks_isa = masks::available();
        let masks = match masks_isa {
            Some(_) => trees.iter().map(masks::MaskTree::new).collect(),
            None => Vec::new(),
        };
        Forest {
            trees,
            classes,
            params,
            by_node,
            masks,
            masks_isa,
        }
    }

    pub fn classes(&self) -> usize {
        self.classes
    }

    pub fn tree_count(&self) -> usize {
        self.trees.len()
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

    /// Probabilities of many pixels: `classes` values per pixel, row after row. Equal, bit for
    /// bit, to [`Forest::predict`] of each pixel (the same sums in the same tree order).
    pub fn predict_many(&self, features: &[FeatureVector]) -> Vec<f32> {
        let k = self.classes;
        let groups = k.div_ceil(4);
        let mut out = vec![0f32; features.len() * k];
        let inv = 1.0 / self.trees.len() as f32;
        out.par_chunks_mut(BLOCK * k)
            .zip(features.par_chunks(BLOCK))
            .with_min_len(crate::pool::min_split(features.len().div_ceil(BLOCK), 1))
            .for_each(|(o, fs)| {
                let mut sum = |state: Option<&mut MaskState>| match groups {
                    1 => self.sum_block::<1>(fs, o, inv, state),
                    2 => self.sum_block::<2>(fs, o, inv, state),
                    _ => self.sum_block_any(fs, o, inv, state),
                };
                if self.masks_isa.is_some() {
                    MASK_STATE.with_borrow_mut(|state| sum(Some(self.mask_state(state))))
                } else {
                    sum(None)
                }
            });
        out
    }

    /// The probabilities of one block of pixels, `G` groups of 4 classes each.
    fn sum_block<const G: usize>(
        &self,
        fs: &[FeatureVector],
        o: &mut [f32],
        inv: f32,
        mut state: Option<&mut MaskState>,
    ) {
        let mut sums = vec![[[0f32; 4]; G]; fs.len()];
        for (t, by_node) in self.by_node.iter().enumerate() {
            let (table, _) = by_node.as_chunks::<G>();
            self.walk_block(t, fs, state.as_deref_mut(), |j, node| {
                let (s, p) = (&mut sums[j], &table[node as usize]);
                for g in 0..G {
                    for c in 0..4 {
                        s[g][c] += p[g][c];
                    }
                }
            });
        }
        for (px, s) in o.chunks_exact_mut(self.classes).zip(&sums) {
            for (c, v) in px.iter_mut().enumerate() {
                *v = s[c / 4][c % 4] * inv;
            }
        }
    }

    /// [`Forest::sum_block`] for any number of classes.
    fn sum_block_any(
        &self,
        fs: &[FeatureVector],
        o: &mut [f32],
        inv: f32,
        mut state: Option<&mut MaskState>,
    ) {
        let groups = self.classes.div_ceil(4);
        let mut sums = vec![[0f32; 4]; fs.len() * groups];
        for (t, by_node) in self.by_node.iter().enumerate() {
            self.walk_block(t, fs, state.as_deref_mut(), |j, node| {
                let from = &by_node[node as usize * groups..(node as usize + 1) * groups];
                for (s, p) in sums[j * groups..(j + 1) * groups].iter_mut().zip(from) {
                    for c in 0..4 {
                        s[c] += p[c];
                    }
                }
            });
        }
        for (j, px) in o.chunks_exact_mut(self.classes).enumerate() {
            for (c, v) in px.iter_mut().enumerate() {
                *v = sums[j * groups + c / 4][c % 4] * inv;
            }
        }
    }

    /// This thread's state for the masks, sized for this forest and readied for a new block.
    fn mask_state<'a>(&self, state: &'a mut Option<MaskState>) -> &'a mut MaskState {
        let (nodes, leaves) =
            (self.masks.iter()).fold((0, 0), |(n, l), m| (n.max(m.nodes()), l.max(m.leaves())));
        let s = state.get_or_insert_with(|| MaskState {
            rows: (0..BLOCK / masks::LANES)
                .map(|_| masks::Rows::new())
                .collect(),
            filled: false,
            reach: Vec::new(),
            hit: Vec::new(),
            walk_for: Vec::new(),
        });
        if s.reach.len() < nodes {
            s.reach.resize(nodes, 0);
        }
        if s.hit.len() < leaves + 2 {
            s.hit.resize(leaves + 2, 0);
        }
        // Choices carried from another forest's blocks only steer the first blocks: both ways
        // reach the same leaves.
        s.walk_for.resize(self.trees.len(), 0);
        s.filled = false;
        s
    }

    /// Walks every pixel of `fs` down tree `t`, calling `at_leaf(pixel, leaf node)`: by masks
    /// where the tree takes them and the pixels share their paths, else the lockstep walk (the
    /// same leaves).
    #[inline(always)]
    fn walk_block(
        &self,
        t: usize,
        fs: &[FeatureVector],
        state: Option<&mut MaskState>,
        mut at_leaf: impl FnMut(usize, u32),
    ) {
        #[cfg(target_arch = "x86_64")]
        if let (Some(isa), Some(s)) = (self.masks_isa, state) {
            let tree = &self.masks[t];
            if s.walk_for[t] > 0 {
                s.walk_for[t] -= 1;
            } else {
                if !s.filled {
                    for (rows, chunk) in s.rows.iter_mut().zip(fs.chunks(masks::LANES)) {
                        rows.fill(chunk);
                    }
                    s.filled = true;
                }
                for (c, rows) in s
                    .rows
                    .iter()
                    .enumerate()
                    .take(fs.len().div_ceil(masks::LANES))
                {
                    let base = c * masks::LANES;
                    let n = (fs.len() - base).min(masks::LANES);
                    let valid = if n == masks::LANES {
                        !0
                    } else {
                        (1u64 << n) - 1
                    };
                    // SAFETY: `masks` holds layouts only where `masks::available()` found the
                    // ISA; each lays out a checked tree; the scratch is sized for the largest.
                    let done = unsafe {
                        masks::leaves(isa, tree, rows, valid, &mut s.reach, &mut s.hit, |p, l| {
                            at_leaf(base + p, l)
                        })
                    };
                    if !done {
                        #[cfg(test)]
                        GAVE_UP.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        // The pixels part ways in this tree: walk the rest of the block, and
                        // the next blocks before trying the masks again.
                        self.trees[t].walk_block(&fs[base..], |j, leaf| at_leaf(base + j, leaf));
                        s.walk_for[t] = WALK_BLOCKS_AFTER_MASKS_FAIL;
                        break;
                    }
                }
                return;
            }
        }
        self.trees[t].walk_block(fs, at_leaf)
    }

    /// The most nodes in one tree.
    #[cfg(test)]
    fn nodes_max(&self) -> usize {
        self.trees.iter().map(|t| t.nodes.len()).max().unwrap_or(0)
    }

    /// Longest path of each tree.
    pub fn depths(&self) -> Vec<u32> {
        self.trees.iter().map(|t| t.depth).collect()
    }
}

/// Pixels per task of [`Forest::predict_many`]: each tree walks them all while it is in cache
/// (256: their features, 18 KB, stay in L1 beside the tree; 1024 gave 6.4 against 7.2 million
/// pixels a second on the forest bench).
const BLOCK: usize = 256;

thread_local! {
    /// Each thread's [`MaskState`], kept from call to call (the fit asks for a few hundred
    /// pixels at a time).
    static MASK_STATE: std::cell::RefCell<Option<MaskState>> = const { std::cell::RefCell::new(None) };
}

/// Blocks of 64 pixels the masks gave up, counted for the tests.
#[cfg(test)]
static GAVE_UP: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

/// Blocks a tree is walked after its pixels part ways too much for the masks (a block walked
/// costs less than one block of masks given up).
const WALK_BLOCKS_AFTER_MASKS_FAIL: u8 = 7;

/// One worker's state for the masks, from block to block: the block's features transposed
/// (`filled` once done for the current block), the masks' scratch, and per tree how many more
/// blocks to walk.
struct MaskState {
    rows: Vec<Box<masks::Rows>>,
    filled: bool,
    reach: Vec<u64>,
    hit: Vec<u32>,
    walk_for: Vec<u8>,
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
    /// Walks every pixel of `fs` to its leaf, calling `at_leaf(pixel, leaf node)`. LANES walks
    /// go in lockstep so their dependent loads overlap, checked every STEPS steps for all of
    /// them having reached their leaves: a group runs as long as its deepest walk, so fewer
    /// lanes and frequent, cheap checks waste less. One thread, 20 trees, the forest bench,
    /// lanes/steps in the same run: 16/4 with the check through `leaf_of` (the earlier walk)
    /// 214 ns per pixel; 16/2 207; 8/2 196; 8/3 198; 8/4 202; 12/2 211; 4/2 244; and one walk
    /// per lane handed the next pixel as soon as it ends, 490 (a mispredicted branch per walk).
    /// Ending on the node's own padded probabilities (`Forest::by_node`) instead of `leaf_of`
    /// then `leaves` class by class: 220 → 184 ns per pixel (the walks alone take ~148).
    #[inline(always)]
    fn walk_block(&self, fs: &[FeatureVector], mut at_leaf: impl FnMut(usize, u32)) {
        const LANES: usize = 8;
        const STEPS: usize = 2;
        let (groups, rest) = fs.as_chunks::<LANES>();
        for (g, group) in groups.iter().enumerate() {
            let mut idx = [0u32; LANES];
            let mut steps = 0;
            while steps < self.depth {
                for _ in 0..STEPS - 1 {
                    for l in 0..LANES {
                        idx[l] = self.step(idx[l], &group[l]);
                    }
                }
                // A walk at its leaf steps onto itself (a split's children come after it), so
                // no index moving in a step means every lane is at its leaf.
                let mut moved = 0u32;
                for l in 0..LANES {
                    let next = self.step(idx[l], &group[l]);
                    moved |= next ^ idx[l];
                    idx[l] = next;
                }
                steps += STEPS as u32;
                if moved == 0 {
                    break;
                }
            }
            for (l, &i) in idx.iter().enumerate() {
                at_leaf(g * LANES + l, i);
            }
        }
        let done = fs.len() - rest.len();
        for (j, f) in rest.iter().enumerate() {
            at_leaf(done + j, self.leaf_node(f));
        }
    }

    /// One step of a walk from node `i` (a leaf steps onto itself).
    #[inline(always)]
    fn step(&self, i: u32, f: &FeatureVector) -> u32 {
        // SAFETY: every tree is either built by `train::TreeBuilder` or deserialised through
        // `Forest::try_from(ForestData)` (which runs `Tree::check`); both guarantee that `i`
        // (the root or a child index) is below `nodes.len()`, that a split's `child + 1` is
        // too, and that `feature` is below FEATURE_COUNT (the length of `f`). This is the
        // forest's hot loop: bounds checks here cost a third of inference time.
        unsafe {
            let n = self.nodes.get_unchecked(i as usize);
            n.child + (*f.get_unchecked(n.feature as usize) > n.threshold) as u32
        }
    }

    /// Checks the invariants the walks rely on: every index in range, a leaf's feature
    /// included (a leaf steps onto itself, reading it); a split's children after it, so every
    /// walk goes forward and ends at a leaf; no path longer than `depth` (the lockstep walk
    /// takes at most that many steps before it reads the leaves).
    fn check(&self, classes: usize) -> Result<(), TreeError> {
        let n = self.nodes.len();
        if n == 0 || self.leaf_of.len() != n {
            return Err(TreeError::Shape);
        }
        // The longest path from the root to each node (children come after their parents).
        let mut level = vec![0u32; n];
        // A node reached from two splits makes a graph, not a tree: the masks (`masks`) lay a
        // tree out as paths from the root and would visit such a node once per path.
        let mut has_parent = vec![false; n];
        for (i, node) in self.nodes.iter().enumerate() {
            if node.feature as usize >= FEATURE_COUNT {
                return Err(TreeError::Split { node: i });
            }
            match self.leaf_of[i] {
                INTERNAL => {
                    let child = node.child as usize;
                    if child <= i || child + 1 >= n {
                        return Err(TreeError::Split { node: i });
                    }
                    for c in [child, child + 1] {
                        if std::mem::replace(&mut has_parent[c], true) {
                            return Err(TreeError::Shared { node: c });
                        }
                        level[c] = level[c].max(level[i] + 1);
                    }
                }
                at => {
                    if node.child as usize != i
                        || node.threshold != u8::MAX
                        || at as usize + classes > self.leaves.len()
                    {
                        return Err(TreeError::Leaf { node: i });
                    }
                    if level[i] > self.depth {
                        return Err(TreeError::Depth);
                    }
                }
            }
        }
        Ok(())
    }

    /// Offset of the probabilities of the leaf `f` reaches, in `leaves`.
    #[inline]
    fn leaf(&self, f: &FeatureVector) -> usize {
        self.leaf_of[self.leaf_node(f) as usize] as usize
    }

    /// The leaf node `f` reaches.
    #[inline]
    fn leaf_node(&self, f: &FeatureVector) -> u32 {
        let mut i = 0usize;
        while self.leaf_of[i] == INTERNAL {
            let node = self.nodes[i];
            i = node.child as usize + (f[node.feature as usize] > node.threshold) as usize;
        }
        i as u32
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// Three classes separated by thresholds on two features, plus noise features (all the
    /// others: 70 of 72, so a split sees an informative one rarely).
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
            trees: 20,
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

    /// The block walk (lockstep lanes, per-node padded probabilities, 1, 2 or more groups of
    /// 4 classes) gives each pixel exactly what the plain one-pixel walk gives.
    #[test]
    fn block_prediction_equals_one_pixel_walks_for_any_class_count() {
        for classes in [2usize, 5, 8, 11] {
            let mut s = toy(3000, 9);
            for (i, c) in s.classes.iter_mut().enumerate() {
                // Spread over `classes` classes by the same two features, plus a little noise.
                let f = s.features[i];
                *c = ((f[3] as usize * classes / 256 + (f[7] as usize).is_multiple_of(3) as usize)
                    % classes) as u8;
            }
            let params = ForestParams {
                trees: 7,
                ..ForestParams::default()
            };
            let (forest, _) = Forest::train(&s, classes, &params).unwrap();
            // 1,001 pixels: blocks of 256 and a remainder that is not a multiple of 8.
            let test = toy(1001, 10);
            let many = forest.predict_many(&test.features);
            let mut one = vec![0f32; classes];
            for (j, f) in test.features.iter().enumerate() {
                forest.predict(f, &mut one);
                assert_eq!(
                    &one[..],
                    &many[j * classes..(j + 1) * classes],
                    "{classes} classes, pixel {j}"
                );
            }
        }
    }

    /// Large trees (a fifth of the labels noise) on pixels in random order make the masks give
    /// blocks up for the walk, and on smooth pixels keep them: either way, and across calls
    /// that carry a thread's choices over, every pixel's probabilities are the one-pixel walk's.
    #[test]
    fn prediction_equals_one_pixel_walks_whether_blocks_take_masks_or_walk() {
        let mut s = toy(20_000, 21);
        let mut rng = Rng::new(22);
        for c in s.classes.iter_mut() {
            if rng.below(5) == 0 {
                *c = rng.below(3) as u8;
            }
        }
        let params = ForestParams {
            trees: 4,
            ..ForestParams::default()
        };
        let (forest, _) = Forest::train(&s, 3, &params).unwrap();
        let random = toy(3000, 23).features;
        let smooth: Vec<FeatureVector> = (0..3000)
            .map(|p| std::array::from_fn(|f| ((p * (f + 1)) / 9 % 256) as u8))
            .collect();
        for (name, fs) in [
            ("random", &random),
            ("smooth", &smooth),
            ("random", &random),
        ] {
            let many = forest.predict_many(fs);
            let mut one = vec![0f32; 3];
            for (j, f) in fs.iter().enumerate() {
                forest.predict(f, &mut one);
                assert_eq!(&one[..], &many[j * 3..(j + 1) * 3], "{name} pixel {j}");
            }
        }
    }

    /// On one fresh thread (its own mask state): a small forest, then a large one (the state
    /// grows), on 64 alike pixels then 192 random ones, so a block's masks succeed on its first
    /// 64 pixels and give up on the next (the walk starts mid-block). Every pixel's
    /// probabilities are still the one-pixel walk's.
    #[test]
    fn masks_give_up_mid_block_and_grow_their_state_between_forests() {
        let train = |noise_every: usize, seed: u64| {
            let mut s = toy(20_000, seed);
            let mut rng = Rng::new(seed + 1);
            for c in s.classes.iter_mut() {
                if rng.below(noise_every) == 0 {
                    *c = rng.below(3) as u8;
                }
            }
            let params = ForestParams {
                trees: 3,
                ..ForestParams::default()
            };
            Forest::train(&s, 3, &params).unwrap().0
        };
        let (small, large) = (train(1_000_000, 31), train(3, 32));
        assert!(small.nodes_max() < large.nodes_max());
        let mut fs = vec![[128u8; FEATURE_COUNT]; 64];
        fs.extend(toy(192, 33).features);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let gave_up = GAVE_UP.load(std::sync::atomic::Ordering::Relaxed);
        for forest in [&small, &large] {
            let many = pool.install(|| forest.predict_many(&fs));
            let mut one = vec![0f32; 3];
            for (j, f) in fs.iter().enumerate() {
                forest.predict(f, &mut one);
                assert_eq!(&one[..], &many[j * 3..(j + 1) * 3], "pixel {j}");
            }
        }
        if masks::available().is_some() {
            assert!(
                GAVE_UP.load(std::sync::atomic::Ordering::Relaxed) > gave_up,
                "the large forest's random pixels should make the masks give up"
            );
        }
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
        // A file must not make a walk read outside a pixel's features, loop, or stop short of
        // a leaf: a leaf's feature out of range, a split pointing back, a depth too small.
        let leaf = v_leaf(&json);
        let mut v: serde_json::Value = serde_json::from_str(&json).unwrap();
        v["trees"][0]["nodes"][leaf]["feature"] = 60000.into();
        assert!(serde_json::from_value::<Forest>(v).is_err());
        let mut v: serde_json::Value = serde_json::from_str(&json).unwrap();
        let last_split = (0..leaf)
            .rev()
            .find(|&i| v["trees"][0]["leaf_of"][i].as_u64() == Some(INTERNAL as u64));
        if let Some(i) = last_split.filter(|&i| i > 0) {
            v["trees"][0]["nodes"][i]["child"] = 0.into();
            assert!(serde_json::from_value::<Forest>(v).is_err());
        }
        let mut v: serde_json::Value = serde_json::from_str(&json).unwrap();
        v["trees"][0]["depth"] = 0.into();
        let err = serde_json::from_value::<Forest>(v).unwrap_err().to_string();
        assert!(err.contains("depth"), "{err}");
    }

    /// Splits sharing children (a graph, not a tree: 0 → 1, 2; 1 and 2 → 3, 4; 3 and 4 →
    /// 5, 6) are refused, though every path is short and goes forward.
    #[test]
    fn a_graph_whose_splits_share_children_is_refused() {
        let tree = Tree {
            nodes: vec![
                Node::split(0, 100, 1),
                Node::split(1, 100, 3),
                Node::split(2, 100, 3),
                Node::split(3, 100, 5),
                Node::split(4, 100, 5),
                Node::leaf(5),
                Node::leaf(6),
            ],
            leaf_of: vec![INTERNAL, INTERNAL, INTERNAL, INTERNAL, INTERNAL, 0, 2],
            leaves: vec![1.0, 0.0, 0.0, 1.0],
            depth: 3,
        };
        assert_eq!(tree.check(2), Err(TreeError::Shared { node: 3 }));
    }

    /// The index of tree 0's first leaf in a serialised forest.
    fn v_leaf(json: &str) -> usize {
        let v: serde_json::Value = serde_json::from_str(json).unwrap();
        v["trees"][0]["leaf_of"]
            .as_array()
            .unwrap()
            .iter()
            .position(|l| l.as_u64() != Some(INTERNAL as u64))
            .unwrap()
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
                .to_string()
                .contains("class 2 has no samples")
        );
    }
}
