//! Binary masks on a cropped block of the label volume: connected components, cavity filling,
//! and the repair that makes a mask *well-composed* (no two voxels, or two gaps, that touch only
//! along an edge or at a corner). Surface nets on a well-composed mask give an edge- and
//! vertex-manifold surface, so the kidney and tumour meshes are watertight by construction
//! rather than patched afterwards.

/// A boolean mask on a block of voxels; `origin` is the block's first voxel in the volume.
#[derive(Debug, Clone, PartialEq)]
pub struct Mask {
    pub dims: [usize; 3],
    pub origin: [isize; 3],
    pub data: Vec<bool>,
}

impl Mask {
    pub fn new(dims: [usize; 3], origin: [isize; 3]) -> Self {
        Self {
            dims,
            origin,
            data: vec![false; dims[0] * dims[1] * dims[2]],
        }
    }

    pub fn index(&self, i: usize, j: usize, k: usize) -> usize {
        i + self.dims[0] * (j + self.dims[1] * k)
    }

    pub fn get(&self, i: isize, j: isize, k: isize) -> bool {
        if i < 0 || j < 0 || k < 0 {
            return false;
        }
        let (i, j, k) = (i as usize, j as usize, k as usize);
        if i >= self.dims[0] || j >= self.dims[1] || k >= self.dims[2] {
            return false;
        }
        self.data[self.index(i, j, k)]
    }

    pub fn count(&self) -> usize {
        self.data.iter().filter(|&&v| v).count()
    }

    /// The same mask with `pad` empty voxels on every side.
    pub fn padded(&self, pad: usize) -> Mask {
        let d = self.dims.map(|n| n + 2 * pad);
        let mut out = Mask::new(d, self.origin.map(|o| o - pad as isize));
        for k in 0..self.dims[2] {
            for j in 0..self.dims[1] {
                for i in 0..self.dims[0] {
                    if self.data[self.index(i, j, k)] {
                        let n = out.index(i + pad, j + pad, k + pad);
                        out.data[n] = true;
                    }
                }
            }
        }
        out
    }
}

/// 6-connected components of `inside(n)` over a grid of `dims`: a component id per voxel
/// (`u32::MAX` outside) and each component's voxel count.
pub fn components(dims: [usize; 3], inside: impl Fn(usize) -> bool) -> (Vec<u32>, Vec<usize>) {
    let total = dims[0] * dims[1] * dims[2];
    let mut id = vec![u32::MAX; total];
    let mut sizes = Vec::new();
    let mut stack = Vec::new();
    for start in 0..total {
        if id[start] != u32::MAX || !inside(start) {
            continue;
        }
        let c = sizes.len() as u32;
        id[start] = c;
        stack.push(start);
        let mut size = 0;
        while let Some(n) = stack.pop() {
            size += 1;
            for m in neighbours6(dims, n) {
                if id[m] == u32::MAX && inside(m) {
                    id[m] = c;
                    stack.push(m);
                }
            }
        }
        sizes.push(size);
    }
    (id, sizes)
}

/// The (i, j, k) of flat index `n` on a grid of `dims` (i fastest, as NIfTI stores it).
pub fn unflatten(dims: [usize; 3], n: usize) -> [usize; 3] {
    [
        n % dims[0],
        (n / dims[0]) % dims[1],
        n / (dims[0] * dims[1]),
    ]
}

/// The up to six face neighbours of voxel `n`.
pub fn neighbours6(dims: [usize; 3], n: usize) -> impl Iterator<Item = usize> {
    let [i, j, k] = unflatten(dims, n);
    let (sx, sy) = (1, dims[0]);
    let sz = dims[0] * dims[1];
    [
        (i > 0).then(|| n - sx),
        (i + 1 < dims[0]).then(|| n + sx),
        (j > 0).then(|| n - sy),
        (j + 1 < dims[1]).then(|| n + sy),
        (k > 0).then(|| n - sz),
        (k + 1 < dims[2]).then(|| n + sz),
    ]
    .into_iter()
    .flatten()
}

/// Keeps only the largest 6-connected component; returns the voxels removed.
pub fn keep_largest(mask: &mut Mask) -> usize {
    let (id, sizes) = components(mask.dims, |n| mask.data[n]);
    let Some(best) = (0..sizes.len()).max_by_key(|&c| sizes[c]) else {
        return 0;
    };
    let mut removed = 0;
    for (v, &c) in mask.data.iter_mut().zip(&id) {
        if *v && c as usize != best {
            *v = false;
            removed += 1;
        }
    }
    removed
}

/// Fills enclosed cavities: background not 6-connected to the block's border becomes inside.
pub fn fill_cavities(mask: &mut Mask) -> usize {
    let m = mask.padded(1);
    let (id, _) = components(m.dims, |n| !m.data[n]);
    // Voxel 0 is in the padding, so its component is the outside.
    let outside = id[0];
    let mut filled = 0;
    for k in 0..mask.dims[2] {
        for j in 0..mask.dims[1] {
            for i in 0..mask.dims[0] {
                let n = mask.index(i, j, k);
                if !mask.data[n] && id[m.index(i + 1, j + 1, k + 1)] != outside {
                    mask.data[n] = true;
                    filled += 1;
                }
            }
        }
    }
    filled
}

/// Adds voxels until no critical configuration is left: in any 2×2 square of the three axis
/// planes exactly two diagonal voxels set, or in any 2×2×2 cube exactly two opposite corners set
/// (or exactly two opposite corners empty). Returns the voxels added. The mask must have one
/// empty voxel of padding on every side (so a critical configuration never reaches past it).
pub fn make_well_composed(mask: &mut Mask) -> usize {
    let [nx, ny, nz] = mask.dims;
    let mut added = 0;
    for _pass in 0..64 {
        let mut changed = 0;
        for k in 0..nz.saturating_sub(1) {
            for j in 0..ny.saturating_sub(1) {
                for i in 0..nx.saturating_sub(1) {
                    changed += fix_cube(mask, i, j, k);
                }
            }
        }
        added += changed;
        if changed == 0 {
            break;
        }
    }
    added
}

/// Repairs the critical configurations inside the cube with lowest corner (i, j, k).
fn fix_cube(mask: &mut Mask, i: usize, j: usize, k: usize) -> usize {
    let at = |c: usize| (i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1));
    let mut v = [false; 8];
    for (c, slot) in v.iter_mut().enumerate() {
        let (a, b, d) = at(c);
        *slot = mask.data[mask.index(a, b, d)];
    }
    let set = |mask: &mut Mask, c: usize| {
        let (a, b, d) = at(c);
        let n = mask.index(a, b, d);
        mask.data[n] = true;
    };
    // The three faces through the lowest corner (the cube's other faces are the lowest faces
    // of neighbouring cubes): corners as bits x = 1, y = 2, z = 4.
    for face in [[0, 1, 2, 3], [0, 1, 4, 5], [0, 2, 4, 6]] {
        let [a, b, c, d] = face.map(|f| v[f]);
        // a b / c d with a, d diagonal.
        if a && d && !b && !c {
            set(mask, face[1]);
            return 1;
        }
        if b && c && !a && !d {
            set(mask, face[0]);
            return 1;
        }
    }
    let count = v.iter().filter(|&&x| x).count();
    for c in 0..4 {
        let opposite = 7 - c;
        // Two opposite corners alone, or the only two gaps.
        if count == 2 && v[c] && v[opposite] {
            set(mask, c ^ 1);
            return 1;
        }
        if count == 6 && !v[c] && !v[opposite] {
            set(mask, c);
            return 1;
        }
    }
    0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn components_cavities_and_critical_configurations() {
        let mut m = Mask::new([8, 8, 8], [0, 0, 0]);
        // A hollow 4×4×4 box (a cavity in the middle) and a separate voxel.
        for k in 2..6 {
            for j in 2..6 {
                for i in 2..6 {
                    let shell = [i, j, k].iter().any(|&x| x == 2 || x == 5);
                    let n = m.index(i, j, k);
                    m.data[n] = shell;
                }
            }
        }
        let lone = m.index(7, 0, 0);
        m.data[lone] = true;
        let (_, sizes) = components(m.dims, |n| m.data[n]);
        assert_eq!(sizes.len(), 2);
        assert!(sizes.contains(&(64 - 8)) && sizes.contains(&1));
        assert_eq!(fill_cavities(&mut m), 8);

        // Two voxels touching along an edge only, and two at a corner only.
        let mut e = Mask::new([6, 6, 6], [0, 0, 0]);
        for (i, j, k) in [(1, 1, 1), (2, 2, 1), (3, 3, 3), (4, 4, 4)] {
            let n = e.index(i, j, k);
            e.data[n] = true;
        }
        let added = make_well_composed(&mut e);
        assert!(added >= 2, "added {added}");
        for k in 0..5 {
            for j in 0..5 {
                for i in 0..5 {
                    assert_eq!(
                        fix_cube(&mut e.clone(), i, j, k),
                        0,
                        "critical at {i},{j},{k}"
                    );
                }
            }
        }
        // The repair only adds.
        for (i, j, k) in [(1, 1, 1), (2, 2, 1), (3, 3, 3), (4, 4, 4)] {
            assert!(e.get(i, j, k));
        }
    }
}
