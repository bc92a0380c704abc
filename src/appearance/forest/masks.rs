//! Leaves of 64 pixels at once, by masks (AVX-512BW, or AVX2): a 64-bit mask per node says
//! which of a block's pixels reach it (the root: all of them), and a split makes its children's
//! masks by comparing one feature of all 64 pixels with its threshold in one instruction (two
//! with AVX2). Splits are visited depth first and a subtree no pixel reaches is skipped whole,
//! so a block pays once per split its pixels reach, with no chain of dependent loads, where a
//! walk pays per pixel per level; leaves reached are listed without a branch. It wins while a
//! block's pixels share most of their paths (neighbours in an image, trees of a few hundred
//! nodes): when they part ways a block gives the masks up after a budget of splits and is walked
//! (`Tree::walk_block`, the reference: both end every pixel on the same leaf).

use super::{INTERNAL, Tree};
use crate::appearance::features::{FEATURE_COUNT, FeatureVector};
#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;

/// Splits a block of 64 pixels may reach, per level of the tree's mean leaf depth, before the
/// masks give it up for the walk. Each split reached costs ~8–10 ns (a branch mispredicted
/// now and then, the masks' loads and stores), a walk ~0.75 ns a level a pixel. Chosen on the
/// forest bench (1 thread; pixels in image order and shuffled; clean labels: trees of ~220
/// nodes, mean leaf depth 8.8; 5 % of labels noise: ~2,300 nodes, depth 16): 6 lost on large
/// trees in image order, 12 on large trees shuffled; the walk wins there by 0–20 % whatever
/// the setting, the masks win by 1.2–1.7× on small trees either way.
const BUDGET_PER_LEVEL: f64 = 10.0;

/// Pixels a block.
pub(super) const LANES: usize = 64;

/// A block's features transposed: row `f` holds feature `f` of its 64 pixels.
#[repr(C, align(64))]
pub(super) struct Rows(pub [[u8; LANES]; FEATURE_COUNT]);

impl Rows {
    pub(super) fn new() -> Box<Rows> {
        Box::new(Rows([[0; LANES]; FEATURE_COUNT]))
    }

    /// Transposes up to 64 pixels' features into the rows (the rest keep what they held:
    /// their lanes are outside the block's mask).
    pub(super) fn fill(&mut self, fs: &[FeatureVector]) {
        let fs = &fs[..fs.len().min(LANES)];
        #[cfg(target_arch = "x86_64")]
        if fs.len() == LANES {
            // SAFETY: SSE2 is part of x86_64; a full block has 64 pixels.
            unsafe { self.fill_full_sse2(fs) };
            return;
        }
        for (p, f) in fs.iter().enumerate() {
            for (row, &v) in self.0.iter_mut().zip(f) {
                row[p] = v;
            }
        }
    }

    /// [`Rows::fill`] of 64 pixels in tiles of 8 pixels × 8 features, each transposed in
    /// registers (three rounds of interleaving): ~10 times the byte-by-byte loop's speed.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "sse2")]
    unsafe fn fill_full_sse2(&mut self, fs: &[FeatureVector]) {
        const { assert!(FEATURE_COUNT.is_multiple_of(8)) };
        // SAFETY: 64 pixels of FEATURE_COUNT bytes; every load reads 8 bytes of a pixel at a
        // feature offset below FEATURE_COUNT − 7, every store 8 bytes of a row at a pixel offset
        // below 57.
        unsafe {
            for p0 in (0..LANES).step_by(8) {
                for f0 in (0..FEATURE_COUNT).step_by(8) {
                    let load =
                        |p: usize| _mm_loadl_epi64(fs[p0 + p].as_ptr().add(f0) as *const __m128i);
                    let a = [
                        load(0),
                        load(1),
                        load(2),
                        load(3),
                        load(4),
                        load(5),
                        load(6),
                        load(7),
                    ];
                    // Pixel pairs interleaved byte by byte, then 16-bit pairs, then 32-bit.
                    let b = [
                        _mm_unpacklo_epi8(a[0], a[1]),
                        _mm_unpacklo_epi8(a[2], a[3]),
                        _mm_unpacklo_epi8(a[4], a[5]),
                        _mm_unpacklo_epi8(a[6], a[7]),
                    ];
                    let c = [
                        _mm_unpacklo_epi16(b[0], b[1]),
                        _mm_unpackhi_epi16(b[0], b[1]),
                        _mm_unpacklo_epi16(b[2], b[3]),
                        _mm_unpackhi_epi16(b[2], b[3]),
                    ];
                    let d = [
                        _mm_unpacklo_epi32(c[0], c[2]),
                        _mm_unpackhi_epi32(c[0], c[2]),
                        _mm_unpacklo_epi32(c[1], c[3]),
                        _mm_unpackhi_epi32(c[1], c[3]),
                    ];
                    // Each d holds two features' 8 pixels: the low half, then the high half.
                    for (k, v) in d.iter().enumerate() {
                        let lo = self.0[f0 + 2 * k].as_mut_ptr().add(p0) as *mut __m128i;
                        let hi = self.0[f0 + 2 * k + 1].as_mut_ptr().add(p0) as *mut __m128i;
                        _mm_storel_epi64(lo, *v);
                        _mm_storel_epi64(hi, _mm_unpackhi_epi64(*v, *v));
                    }
                }
            }
        }
    }
}

/// A split as the masks need it.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Split {
    node: u32,
    child: u32,
    /// Index in `MaskTree::splits` of the first split after this one's subtree.
    skip: u32,
    feature: u16,
    threshold: u8,
    /// Bit 0: the left child is a leaf; bit 1: the right one.
    leaf_children: u8,
}

/// A tree laid out for the masks: its splits in depth-first order, each with the place to skip
/// to when no pixel reaches it.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct MaskTree {
    splits: Vec<Split>,
    nodes: usize,
    leaves: usize,
    /// Splits a block may reach before walking it is cheaper ([`BUDGET_PER_LEVEL`] per level
    /// of the tree's mean leaf depth).
    budget: u32,
}

impl MaskTree {
    /// The layout of a checked tree.
    pub(super) fn new(tree: &Tree) -> MaskTree {
        let is_leaf = |i: u32| tree.leaf_of[i as usize] != INTERNAL;
        let mut splits: Vec<Split> = Vec::new();
        // Depth first without recursion (a deserialised tree may be deep), each node with its
        // level: `true` closes a split's subtree, setting its skip.
        let mut stack = vec![(0u32, 0u32, false)];
        let mut open = Vec::new();
        let mut depth_sum = 0u64;
        while let Some((i, level, close)) = stack.pop() {
            if close {
                let after = splits.len() as u32;
                if let Some(s) = open.pop().and_then(|at: usize| splits.get_mut(at)) {
                    s.skip = after;
                }
                continue;
            }
            if is_leaf(i) {
                depth_sum += level as u64;
                continue;
            }
            let n = tree.nodes[i as usize];
            open.push(splits.len());
            splits.push(Split {
                node: i,
                child: n.child,
                skip: 0,
                feature: n.feature,
                threshold: n.threshold,
                leaf_children: is_leaf(n.child) as u8 | (is_leaf(n.child + 1) as u8) << 1,
            });
            stack.extend([
                (i, level, true),
                (n.child + 1, level + 1, false),
                (n.child, level + 1, false),
            ]);
        }
        // Leaves the splits can list (each leaf child once; the root when it is the only
        // node): the bound on a block's hits whatever the layout.
        let leaves = (splits.iter())
            .map(|s| s.leaf_children.count_ones() as usize)
            .sum::<usize>()
            .max(1);
        let mean_depth = depth_sum as f64 / leaves as f64;
        MaskTree {
            splits,
            nodes: tree.nodes.len(),
            leaves,
            budget: (BUDGET_PER_LEVEL * mean_depth).ceil() as u32,
        }
    }

    pub(super) fn nodes(&self) -> usize {
        self.nodes
    }

    pub(super) fn leaves(&self) -> usize {
        self.leaves
    }
}

/// Which vector instructions the masks use: AVX-512BW compares 64 bytes into a mask at once,
/// AVX2 two halves of 32.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Isa {
    Avx512,
    Avx2,
}

/// Can this CPU take the masks, and with which instructions? (The standard library asks the
/// CPU once.) The environment variable `ENDOFUSE_FOREST_WALK` turns the masks off and
/// `ENDOFUSE_FOREST_AVX2` keeps them to AVX2, for benchmarks side by side.
pub(super) fn available() -> Option<Isa> {
    #[cfg(target_arch = "x86_64")]
    {
        if std::env::var_os("ENDOFUSE_FOREST_WALK").is_some() {
            return None;
        }
        if std::env::var_os("ENDOFUSE_FOREST_AVX2").is_none()
            && std::arch::is_x86_feature_detected!("avx512f")
            && std::arch::is_x86_feature_detected!("avx512bw")
        {
            return Some(Isa::Avx512);
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            return Some(Isa::Avx2);
        }
    }
    None
}

/// Calls `at_leaf(lane, leaf node)` for each of the block's pixels (`valid`: which lanes hold
/// pixels), leaf by leaf, and returns true; or returns false, having called nothing, when the
/// pixels reach more splits than `MaskTree::budget` (they take different paths: walking them
/// costs less). `reach` and `hit` are scratch of at least the tree's node count and leaf
/// count + 2.
///
/// # Safety
/// The CPU has `isa` (as [`available`] found); `tree` lays out a checked tree (children after
/// their parents, inside the node count; features below FEATURE_COUNT); the scratch is large
/// enough.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(super) unsafe fn leaves(
    isa: Isa,
    tree: &MaskTree,
    rows: &Rows,
    valid: u64,
    reach: &mut [u64],
    hit: &mut [u32],
    at_leaf: impl FnMut(usize, u32),
) -> bool {
    // SAFETY: the caller's contract.
    unsafe {
        match isa {
            Isa::Avx512 => leaves_avx512(tree, rows, valid, reach, hit, at_leaf),
            Isa::Avx2 => leaves_avx2(tree, rows, valid, reach, hit, at_leaf),
        }
    }
}

/// [`leaves`] with AVX-512BW: one compare of 64 bytes into a mask.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512bw")]
unsafe fn leaves_avx512(
    tree: &MaskTree,
    rows: &Rows,
    valid: u64,
    reach: &mut [u64],
    hit: &mut [u32],
    at_leaf: impl FnMut(usize, u32),
) -> bool {
    // SAFETY: the caller's contract; a row is 64 bytes aligned to 64.
    unsafe {
        leaves_by(tree, valid, reach, hit, at_leaf, |feature, threshold| {
            let row = _mm512_load_si512(rows.0.as_ptr().add(feature) as *const _);
            _mm512_cmpgt_epu8_mask(row, _mm512_set1_epi8(threshold as i8))
        })
    }
}

/// [`leaves`] with AVX2: a byte is above the threshold where their saturated difference is
/// not zero, found for 32 bytes at a time.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn leaves_avx2(
    tree: &MaskTree,
    rows: &Rows,
    valid: u64,
    reach: &mut [u64],
    hit: &mut [u32],
    at_leaf: impl FnMut(usize, u32),
) -> bool {
    // SAFETY: the caller's contract; a row is 64 bytes aligned to 64.
    unsafe {
        leaves_by(tree, valid, reach, hit, at_leaf, |feature, threshold| {
            let row = rows.0.as_ptr().add(feature) as *const __m256i;
            let t = _mm256_set1_epi8(threshold as i8);
            let zero = _mm256_setzero_si256();
            let at_most = |half: *const __m256i| {
                let d = _mm256_subs_epu8(_mm256_load_si256(half), t);
                _mm256_movemask_epi8(_mm256_cmpeq_epi8(d, zero)) as u32 as u64
            };
            !(at_most(row) | at_most(row.add(1)) << 32)
        })
    }
}

/// The masks' walk of one tree over one block, `right(feature, threshold)` giving the mask of
/// the block's pixels whose feature is above the threshold.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn leaves_by(
    tree: &MaskTree,
    valid: u64,
    reach: &mut [u64],
    hit: &mut [u32],
    mut at_leaf: impl FnMut(usize, u32),
    right: impl Fn(usize, u8) -> u64,
) -> bool {
    debug_assert!(reach.len() >= tree.nodes && hit.len() >= tree.leaves + 2);
    let mut hits = 0usize;
    if tree.splits.is_empty() {
        // The root is the tree's only leaf.
        hit[0] = 0;
        hits = 1;
    }
    let (reach, hit) = (reach.as_mut_ptr(), hit.as_mut_ptr());
    // SAFETY (all the unchecked accesses below): the caller's contract. Every split visited
    // has its mask written this block: the root's here, the others' by their parent, visited
    // before them (depth first); a subtree no pixel reaches is skipped whole. `hit` receives
    // each leaf reached once, plus one slot written and not counted.
    unsafe {
        *reach = valid;
        let mut k = 0usize;
        let mut budget = tree.budget;
        while k < tree.splits.len() {
            let s = tree.splits.get_unchecked(k);
            let r = *reach.add(s.node as usize);
            if r == 0 {
                k = s.skip as usize;
                continue;
            }
            if budget == 0 {
                return false;
            }
            budget -= 1;
            let right = right(s.feature as usize, s.threshold);
            let (left, right) = (r & !right, r & right);
            *reach.add(s.child as usize) = left;
            *reach.add(s.child as usize + 1) = right;
            // Leaf children reached are listed without a branch.
            *hit.add(hits) = s.child;
            hits += (s.leaf_children & 1) as usize & (left != 0) as usize;
            *hit.add(hits) = s.child + 1;
            hits += (s.leaf_children >> 1) as usize & (right != 0) as usize;
            k += 1;
        }
        for q in 0..hits {
            let l = *hit.add(q);
            let mut r = *reach.add(l as usize);
            while r != 0 {
                at_leaf(r.trailing_zeros() as usize, l);
                r &= r - 1;
            }
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::super::{Forest, ForestParams, Node, Samples};
    use super::*;
    use crate::rng::Rng;

    /// Every pixel's leaf by masks with `isa` (which this CPU must have), blocks given up walked.
    fn by_masks(tree: &Tree, fs: &[FeatureVector], isa: Isa) -> Vec<u32> {
        let layout = MaskTree::new(tree);
        let mut reach = vec![0u64; layout.nodes()];
        let mut hit = vec![0u32; layout.leaves() + 2];
        let (mut rows, mut leaf) = (Rows::new(), [0u32; LANES]);
        let mut out = Vec::new();
        for chunk in fs.chunks(LANES) {
            rows.fill(chunk);
            let valid = if chunk.len() == LANES {
                !0
            } else {
                (1u64 << chunk.len()) - 1
            };
            #[cfg(target_arch = "x86_64")]
            // SAFETY: `available()` found the ISA; the tree is checked; scratch sized.
            let done = unsafe {
                leaves(isa, &layout, &rows, valid, &mut reach, &mut hit, |p, l| {
                    leaf[p] = l
                })
            };
            if !done {
                for (p, f) in chunk.iter().enumerate() {
                    leaf[p] = tree.leaf_node(f);
                }
            }
            out.extend_from_slice(&leaf[..chunk.len()]);
        }
        out
    }

    /// The masks, the lockstep walk and one pixel's walk agree on every pixel's leaf.
    fn same_leaves(tree: &Tree, fs: &[FeatureVector], what: &str) {
        tree.check(2).unwrap_or_else(|e| panic!("{what}: {e}"));
        let one: Vec<u32> = fs.iter().map(|f| tree.leaf_node(f)).collect();
        let mut walked = vec![u32::MAX; fs.len()];
        tree.walk_block(fs, |j, node| walked[j] = node);
        assert_eq!(walked, one, "{what}: lockstep walk");
        // Both instruction sets this CPU has.
        let isas = match available() {
            Some(Isa::Avx512) => vec![Isa::Avx512, Isa::Avx2],
            Some(Isa::Avx2) => vec![Isa::Avx2],
            None => vec![],
        };
        for isa in isas {
            let masked = by_masks(tree, fs, isa);
            assert_eq!(masked, one, "{what}: masks ({isa:?})");
        }
    }

    fn random_pixels(n: usize, seed: u64) -> Vec<FeatureVector> {
        let mut rng = Rng::new(seed);
        (0..n)
            .map(|_| std::array::from_fn(|_| rng.below(256) as u8))
            .collect()
    }

    /// Neighbouring pixels alike, as in an image row (most of a block's pixels share paths).
    fn smooth_pixels(n: usize) -> Vec<FeatureVector> {
        (0..n)
            .map(|p| std::array::from_fn(|f| ((p * (f + 1)) / 7 % 256) as u8))
            .collect()
    }

    fn trained_tree(samples: usize, seed: u64) -> Tree {
        let mut s = Samples::default();
        let mut rng = Rng::new(seed);
        for f in random_pixels(samples, seed) {
            // Labels mostly from two features, 20 % at random: deep, bushy trees.
            let noisy = rng.below(5) == 0;
            let class = if noisy {
                rng.below(3)
            } else {
                (f[3] / 90) as usize % 3
            };
            s.push(f, class as u8);
        }
        let params = ForestParams {
            trees: 1,
            ..ForestParams::default()
        };
        let (forest, _): (Forest, _) = Forest::train(&s, 3, &params).unwrap();
        forest.trees[0].clone()
    }

    /// A tree of `n` splits in a chain (each split's left child a leaf): a deep tree whose skips
    /// nest `n` levels.
    fn chain(n: usize) -> Tree {
        let (mut nodes, mut leaf_of, mut leaves) = (Vec::new(), Vec::new(), Vec::new());
        // Node 0 splits; split k's children are 2k+1 (a leaf) and 2k+2 (the next split or, at
        // the end, a leaf).
        for k in 0..n {
            let at = nodes.len() as u32;
            nodes.push(Node::split(
                (k % FEATURE_COUNT) as u16,
                (k * 37 % 250) as u8,
                at + 1,
            ));
            leaf_of.push(INTERNAL);
            let leaf = nodes.len() as u32;
            nodes.push(Node::leaf(leaf));
            leaf_of.push(leaves.len() as u32);
            leaves.extend([1.0, 0.0]);
            if k + 1 == n {
                let last = nodes.len() as u32;
                nodes.push(Node::leaf(last));
                leaf_of.push(leaves.len() as u32);
                leaves.extend([0.0, 1.0]);
            }
        }
        Tree {
            nodes,
            leaf_of,
            leaves,
            depth: n as u32,
        }
    }

    #[test]
    fn masks_lockstep_walk_and_one_pixel_walk_reach_the_same_leaves() {
        if available().is_none() {
            eprintln!("this CPU has no AVX2: only the two walks are compared");
        }
        for (samples, seed) in [(40, 1), (3000, 2), (20_000, 3)] {
            let tree = trained_tree(samples, seed);
            for n in [1, 63, 64, 65, 1001] {
                same_leaves(
                    &tree,
                    &random_pixels(n, seed + 10),
                    "trained, random pixels",
                );
                same_leaves(&tree, &smooth_pixels(n), "trained, smooth pixels");
            }
        }
        let root_only = Tree {
            nodes: vec![Node::leaf(0)],
            leaf_of: vec![0],
            leaves: vec![0.5, 0.5],
            depth: 0,
        };
        same_leaves(&root_only, &random_pixels(70, 4), "one leaf");
        for n in [1, 2, 300] {
            same_leaves(&chain(n), &random_pixels(200, 5), "chain");
            same_leaves(&chain(n), &smooth_pixels(200), "chain, smooth pixels");
        }
    }

    #[test]
    fn a_subtree_no_pixel_reaches_is_skipped_whole() {
        // Node 0 on feature 0 at 127: left 1 (a split on feature 1), right 2 (a leaf); 1's
        // children 3 and 4 are leaves.
        let tree = Tree {
            nodes: vec![
                Node::split(0, 127, 1),
                Node::split(1, 10, 3),
                Node::leaf(2),
                Node::leaf(3),
                Node::leaf(4),
            ],
            leaf_of: vec![INTERNAL, INTERNAL, 0, 2, 4],
            leaves: vec![1.0, 0.0, 0.0, 1.0, 0.5, 0.5],
            depth: 2,
        };
        tree.check(2).unwrap();
        let layout = MaskTree::new(&tree);
        let skips: Vec<(u32, u32)> = layout.splits.iter().map(|s| (s.node, s.skip)).collect();
        assert_eq!(skips, [(0, 2), (1, 2)]);
        // Every pixel right at the root: node 1's subtree is not visited, all end on leaf 2.
        let right: Vec<FeatureVector> = (0..64)
            .map(|p| [200u8.max(p as u8); FEATURE_COUNT])
            .collect();
        same_leaves(&tree, &right, "all right");
        let mixed: Vec<FeatureVector> = (0..64).map(|p| [(p * 4) as u8; FEATURE_COUNT]).collect();
        same_leaves(&tree, &mixed, "mixed");
    }

    #[test]
    fn transposed_rows_hold_each_pixels_features() {
        for n in [64, 10] {
            let fs = random_pixels(n, 7);
            let mut rows = Rows::new();
            rows.fill(&fs);
            for (p, f) in fs.iter().enumerate() {
                for (k, &v) in f.iter().enumerate() {
                    assert_eq!(rows.0[k][p], v, "{n} pixels: pixel {p}, feature {k}");
                }
            }
        }
    }
}
