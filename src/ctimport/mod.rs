//! `import-ct` (CONTRACT §4): a patient's CT label volume (NIfTI; KiTS labels by default) becomes
//! the scene's structures — the kidney on the tumour's side and one structure per tumour
//! component, each a closed, outward, manifold surface in world millimetres, smoothed without
//! shrinkage and decimated, with the deformation catalog of the joint PCA model.
//!
//! The pipeline, per structure: a voxel mask → cavities filled → made well-composed
//! ([`mask`]) → surface nets ([`surface`]) → Taubin smoothing → decimation ([`smooth`]) →
//! topology, self-intersection and volume checks. A tumour is **exophytic (visible)** when at
//! least [`EXPOSED_SHARE`] of its boundary area faces background rather than kidney, and
//! **endophytic (hidden)** otherwise; ct.json records each tumour's numbers. The kidney mesh
//! wraps the kidney label with its cysts and endophytic tumours (the organ a surgeon sees) but
//! not the exophytic ones, which bulge out of it as their own structures.

pub mod mask;
pub mod output;
pub mod smooth;
pub mod surface;
pub mod volume;

use crate::error::{Error, InputError};
use crate::geometry::Mesh;
use glam::DVec3;
use mask::Mask;
use std::path::Path;
use volume::LabelVolume;

/// Share of a tumour's boundary area that must face background (not kidney, not cyst) for it to
/// count as exophytic. Small, so that any real bulge counts, but above label noise: a tumour
/// labelled one voxel short of the kidney surface in a few places stays endophytic.
pub const EXPOSED_SHARE: f64 = 0.02;
/// Tumour components smaller than this are label noise and are dropped (ct.json lists them).
pub const MIN_TUMOUR_MM3: f64 = 20.0;
/// Taubin iterations on the dense surface (before decimation).
pub const SMOOTH_ITERATIONS: usize = 10;
/// The mesh volume must stay within this share of the voxel volume (CONTRACT §4).
pub const VOLUME_TOLERANCE: f64 = 0.03;
/// Deformed copies written per structure (DeformIt's catalog size in the paper).
pub const DEFAULT_CATALOG_SIZE: usize = 40;

/// Which kidney to mesh.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Side {
    /// The kidney the largest tumour touches (the larger kidney without a tumour).
    Auto,
    /// The patient's left (smaller world x in NIfTI's RAS+ coordinates).
    Left,
    Right,
}

impl Side {
    pub fn parse(s: &str) -> Option<Side> {
        match s.to_ascii_lowercase().as_str() {
            "auto" => Some(Side::Auto),
            "left" | "l" => Some(Side::Left),
            "right" | "r" => Some(Side::Right),
            _ => None,
        }
    }
}

/// What `import-ct` is asked to do.
#[derive(Debug, Clone, PartialEq)]
pub struct ImportOptions {
    pub side: Side,
    pub kidney_label: u16,
    pub tumour_label: u16,
    /// Cysts belong to the organ's volume but get no structure of their own.
    pub cyst_label: Option<u16>,
    pub kidney_vertices: usize,
    pub tumour_vertices: usize,
    pub catalog_size: usize,
    /// Replace a non-empty output folder.
    pub force: bool,
}

impl Default for ImportOptions {
    fn default() -> Self {
        Self {
            side: Side::Auto,
            kidney_label: 1,
            tumour_label: 2,
            cyst_label: Some(3),
            kidney_vertices: 5000,
            tumour_vertices: Self::tumour_vertices_for(5000),
            catalog_size: DEFAULT_CATALOG_SIZE,
            force: false,
        }
    }
}

impl ImportOptions {
    /// A tumour's target vertex count for a kidney of `kidney_vertices`: a quarter, at least
    /// 100. `import-ct --vertices` and `new-scene --ct` (the defaults) share it, so the two
    /// mesh a CT alike (a tumour came out at 1,252 vertices from one and 1,202 from the other).
    pub fn tumour_vertices_for(kidney_vertices: usize) -> usize {
        (kidney_vertices / 4).max(100)
    }

    /// Parses `kidney=1,tumour=2[,cyst=3]` into the labels.
    pub fn set_labels(&mut self, spec: &str) -> Result<(), String> {
        for part in spec.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            let (key, value) = part
                .split_once('=')
                .ok_or_else(|| format!("'{part}' is not NAME=LABEL"))?;
            let v: u16 = value
                .trim()
                .parse()
                .map_err(|_| format!("'{value}' is not a label number (0–65535)"))?;
            if v == 0 {
                return Err("label 0 is background".into());
            }
            match key.trim() {
                "kidney" => self.kidney_label = v,
                "tumour" | "tumor" => self.tumour_label = v,
                "cyst" => self.cyst_label = Some(v),
                other => {
                    return Err(format!(
                        "unknown structure '{other}' (kidney, tumour, cyst)"
                    ));
                }
            }
        }
        if self.kidney_label == self.tumour_label {
            return Err("kidney and tumour need different labels".into());
        }
        Ok(())
    }
}

/// Why a tumour is visible or hidden, with the numbers.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Exposure {
    /// Boundary area facing background, mm².
    pub exposed_mm2: f64,
    /// Boundary area facing kidney (or cyst, or another tumour), mm².
    pub enclosed_mm2: f64,
    pub exposed_share: f64,
    pub rule: String,
}

/// One structure as imported.
#[derive(Debug, Clone, serde::Serialize)]
pub struct StructureReport {
    pub name: String,
    pub label: u8,
    pub visible: bool,
    pub voxels: usize,
    pub voxel_volume_mm3: f64,
    pub mesh_volume_mm3: f64,
    /// (mesh − voxel) / voxel.
    pub volume_error: f64,
    pub vertices: usize,
    pub faces: usize,
    pub topology: surface::Topology,
    pub self_intersections: usize,
    /// Voxels added to make the mask well-composed, to fill cavities and to close tunnels.
    pub voxels_added: usize,
    /// Voxels of smaller pieces dropped (a kidney cut in two by an exophytic tumour keeps its
    /// larger piece).
    pub voxels_dropped: usize,
    /// How far the final surface was moved along its normals to restore the voxel volume
    /// (positive outwards), mm.
    pub normal_offset_mm: f64,
    /// (mesh − voxel) / voxel after smoothing and decimation, before that offset.
    pub volume_error_before_offset: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub exposure: Option<Exposure>,
    #[serde(skip)]
    pub mesh: Mesh,
}

/// Everything `import-ct` found and made (ct.json).
#[derive(Debug, Clone, serde::Serialize)]
pub struct ImportReport {
    pub source: String,
    pub dims: [usize; 3],
    pub voxel_size_mm: [f64; 3],
    pub world_transform: volume::WorldTransform,
    pub datatype: String,
    pub side: String,
    pub side_reason: String,
    pub kidneys_found: usize,
    /// World position subtracted from every mesh (the kidney's vertex mean), mm.
    pub recentred_by_mm: [f64; 3],
    pub structures: Vec<StructureReport>,
    /// Tumour components dropped as label noise (voxel counts).
    pub dropped_tumour_voxels: Vec<usize>,
    pub notes: Vec<String>,
}

/// Reads `labels`, builds every structure, and writes them to `out` (see [`output`]).
pub fn import_ct(
    labels: &Path,
    out: &Path,
    options: &ImportOptions,
    progress: &dyn Fn(&str),
) -> Result<ImportReport, Error> {
    output::check_target(out, options.force, &[labels], output::Replaces::MeshesOnly)?;
    let report = read_and_build(labels, options, progress)?;
    progress("writing meshes and the deformation catalog");
    output::write(out, &report, options)?;
    Ok(report)
}

/// Reads the label file and builds its structures; errors name the file.
pub fn read_and_build(
    labels: &Path,
    options: &ImportOptions,
    progress: &dyn Fn(&str),
) -> Result<ImportReport, InputError> {
    progress("reading the label volume");
    let vol = volume::read(labels).map_err(|e| InputError::new(labels, e.to_string()))?;
    let mut report = build(&vol, options, progress).map_err(|p| InputError::new(labels, p))?;
    report.source = labels.display().to_string();
    Ok(report)
}

/// The structures of a label volume (everything but the files). Errors are the problem in
/// words; the caller names the file.
pub fn build(
    vol: &LabelVolume,
    options: &ImportOptions,
    progress: &dyn Fn(&str),
) -> Result<ImportReport, String> {
    let (kl, tl, cl) = (
        options.kidney_label,
        options.tumour_label,
        options.cyst_label,
    );
    let present = vol.labels_present();
    if present.is_empty() {
        return Err("the volume is all background (no labelled voxel)".into());
    }
    if !present.contains(&kl) {
        let found: Vec<String> = present.iter().map(|v| v.to_string()).collect();
        return Err(format!(
            "no voxel has the kidney label {kl} (labels present: {}); use --labels kidney=N,tumour=M",
            found.join(", ")
        ));
    }
    let organ_label = |v: u16| v == kl || v == tl || Some(v) == cl;
    // Work on the bounding block of the organ labels.
    let block = bounding_block(vol, organ_label);
    let label_at = |n: usize| vol.labels[block.volume_index(n)];
    progress("finding the kidneys");
    let (organ_id, organ_sizes) = mask::components(block.dims, |n| organ_label(label_at(n)));
    let (tumour_id, tumour_sizes) = mask::components(block.dims, |n| label_at(n) == tl);
    // One pass for what each component is: its centroid and bounds, whether it holds kidney
    // voxels, and which organ component each tumour lies in.
    let mut organs = vec![ComponentStats::default(); organ_sizes.len()];
    let mut tumour_organ = vec![u32::MAX; tumour_sizes.len()];
    let mut tumour_bounds = vec![ComponentStats::default(); tumour_sizes.len()];
    for n in 0..organ_id.len() {
        let o = organ_id[n];
        if o == u32::MAX {
            continue;
        }
        let ijk = mask::unflatten(block.dims, n);
        organs[o as usize].add(ijk, vol.world(block.ijk(n)), label_at(n) == kl);
        let t = tumour_id[n];
        if t != u32::MAX {
            tumour_organ[t as usize] = o;
            tumour_bounds[t as usize].add(ijk, DVec3::ZERO, false);
        }
    }
    let voxel_mm3 = vol.voxel_volume_mm3();
    // Kidneys: organ components with kidney voxels, at least a fifth of the largest of them.
    let largest = (0..organs.len())
        .filter(|&c| organs[c].kidney_voxels > 0)
        .map(|c| organ_sizes[c])
        .max()
        .unwrap_or(0);
    let kidneys: Vec<u32> = (0..organs.len() as u32)
        .filter(|&c| organs[c as usize].kidney_voxels > 0 && organ_sizes[c as usize] * 5 >= largest)
        .collect();
    let mut notes = Vec::new();
    let centroid = |c: u32| organs[c as usize].centroid();
    let (chosen, side_reason) = choose_kidney(
        &kidneys,
        &organ_sizes,
        &tumour_organ,
        &tumour_sizes,
        options.side,
        &centroid,
    )?;
    let side = if kidneys.len() >= 2 {
        let x = centroid(chosen).x;
        if kidneys
            .iter()
            .filter(|&&c| c != chosen)
            .all(|&c| x > centroid(c).x)
        {
            "right"
        } else {
            "left"
        }
    } else {
        notes.push(
            "one kidney in the volume: which side it is cannot be told from the labels alone"
                .to_string(),
        );
        "unknown"
    };
    // Tumour components inside the chosen organ, largest first; the others are said.
    let elsewhere: Vec<usize> = (0..tumour_sizes.len())
        .filter(|&t| tumour_organ[t] != chosen)
        .map(|t| tumour_sizes[t])
        .collect();
    if !elsewhere.is_empty() {
        notes.push(format!(
            "{} tumour component(s) outside the chosen kidney not imported (voxels: {:?})",
            elsewhere.len(),
            elsewhere
        ));
    }
    let mut tumours: Vec<(u32, usize)> = (0..tumour_sizes.len() as u32)
        .filter(|&t| tumour_organ[t as usize] == chosen)
        .map(|t| (t, tumour_sizes[t as usize]))
        .collect();
    tumours.sort_by_key(|&(t, n)| (std::cmp::Reverse(n), t));
    let mut dropped = Vec::new();
    tumours.retain(|&(_, n)| {
        let keep = n as f64 * voxel_mm3 >= MIN_TUMOUR_MM3;
        if !keep {
            dropped.push(n);
        }
        keep
    });
    if tumours.len() > 253 {
        return Err(format!(
            "{} tumour components: a scene holds at most 253 besides the kidney",
            tumours.len()
        ));
    }
    if tumours.is_empty() {
        notes.push("no tumour in the chosen kidney: the scene has the kidney only".into());
    }
    let spacing = vol.spacing_mm();
    let face_area = [
        spacing[1] * spacing[2],
        spacing[0] * spacing[2],
        spacing[0] * spacing[1],
    ];
    let mut structures = Vec::new();
    let mut exophytic = vec![false; tumour_sizes.len()];
    let (mut n_exo, mut n_endo) = (0, 0);
    let mut tumour_masks = Vec::new();
    for (k, &(t, _)) in tumours.iter().enumerate() {
        let bounds = &tumour_bounds[t as usize];
        let exposure = exposure(&block, bounds, &tumour_id, t, &organ_id, chosen, face_area);
        let visible = exposure.exposed_share >= EXPOSED_SHARE;
        let (base, count) = if visible {
            n_exo += 1;
            ("tumour_exo", n_exo)
        } else {
            n_endo += 1;
            ("tumour_endo", n_endo)
        };
        let name = if count == 1 {
            base.to_string()
        } else {
            format!("{base}_{count}")
        };
        exophytic[t as usize] = visible;
        let m = block.mask_in(bounds, |x| tumour_id[x] == t);
        tumour_masks.push((name, (k + 2) as u8, visible, exposure, m));
    }
    let kidney_mask = block.mask_in(&organs[chosen as usize], |x| {
        organ_id[x] == chosen && (tumour_id[x] == u32::MAX || !exophytic[tumour_id[x] as usize])
    });
    // The component maps are done with: free them before meshing.
    drop((organ_id, tumour_id));
    progress("meshing the kidney");
    if let Some(edge) = touches_volume_edge(&kidney_mask, vol.dims) {
        notes.push(format!(
            "the kidney reaches the scan's edge ({edge}): its surface there is the field of view's cut, not anatomy"
        ));
    }
    structures.push(mesh_structure(
        "kidney",
        1,
        true,
        kidney_mask,
        vol,
        options.kidney_vertices,
    )?);
    for (name, label, visible, exposure, m) in tumour_masks {
        progress(&format!("meshing {name}"));
        let mut s = mesh_structure(&name, label, visible, m, vol, options.tumour_vertices)?;
        s.exposure = Some(exposure);
        structures.push(s);
    }
    let centre = structures[0].mesh.vertex_mean();
    for s in &mut structures {
        for v in &mut s.mesh.vertices {
            *v -= centre;
        }
        if s.self_intersections > 0 {
            notes.push(format!(
                "{}: {} pairs of faces cross (smoothing pressed two close sheets together)",
                s.name, s.self_intersections
            ));
        }
        // Decimation stops where a further collapse would pinch the surface: say when that
        // left far more vertices than asked (`--vertices 10` gave 8,614 with no word).
        let asked = if s.label == 1 {
            options.kidney_vertices
        } else {
            options.tumour_vertices
        };
        if s.vertices > asked + asked / 2 {
            notes.push(format!(
                "{}: {} vertices kept, more than the {asked} asked: fewer would pinch its surface",
                s.name, s.vertices
            ));
        }
        if s.volume_error.abs() > VOLUME_TOLERANCE {
            notes.push(format!(
                "{}: mesh volume differs from the voxel volume by {:.1} % (more than {:.0} %)",
                s.name,
                100.0 * s.volume_error,
                100.0 * VOLUME_TOLERANCE
            ));
        }
    }
    Ok(ImportReport {
        source: String::new(),
        dims: vol.dims,
        voxel_size_mm: spacing,
        world_transform: vol.transform,
        datatype: vol.datatype.clone(),
        side: side.into(),
        side_reason,
        kidneys_found: kidneys.len(),
        recentred_by_mm: centre.to_array(),
        structures,
        dropped_tumour_voxels: dropped,
        notes,
    })
}

/// Picks the organ component to mesh; the reason says why, for ct.json.
fn choose_kidney(
    kidneys: &[u32],
    organ_sizes: &[usize],
    tumour_organ: &[u32],
    tumour_sizes: &[usize],
    side: Side,
    centroid: &dyn Fn(u32) -> DVec3,
) -> Result<(u32, String), String> {
    let by_x = |a: &u32, b: &u32| centroid(*a).x.total_cmp(&centroid(*b).x);
    match side {
        Side::Left | Side::Right => {
            let pick = if side == Side::Right {
                kidneys.iter().copied().max_by(by_x)
            } else {
                kidneys.iter().copied().min_by(by_x)
            };
            let pick = pick.ok_or("no kidney component")?;
            let which = if side == Side::Right { "right" } else { "left" };
            let reason = if kidneys.len() == 1 {
                format!("--side {which}, but the volume holds one kidney: that one")
            } else {
                format!("--side {which}: the kidney at the {which} (world x, RAS+)")
            };
            Ok((pick, reason))
        }
        Side::Auto => {
            // The kidney holding the largest tumour.
            let largest = (0..tumour_sizes.len())
                .filter(|&t| kidneys.contains(&tumour_organ[t]))
                .max_by_key(|&t| tumour_sizes[t]);
            if let Some(t) = largest {
                return Ok((
                    tumour_organ[t],
                    format!(
                        "auto: the kidney the largest tumour ({} voxels) touches",
                        tumour_sizes[t]
                    ),
                ));
            }
            let c = kidneys
                .iter()
                .copied()
                .max_by_key(|&c| organ_sizes[c as usize])
                .ok_or("no kidney component")?;
            Ok((
                c,
                "auto: no tumour touches a kidney, the larger kidney".into(),
            ))
        }
    }
}

/// Per component: voxel bounds (block coordinates), world centroid, kidney-label voxels.
#[derive(Debug, Clone)]
struct ComponentStats {
    lo: [usize; 3],
    hi: [usize; 3],
    sum_mm: DVec3,
    count: usize,
    kidney_voxels: usize,
}

impl Default for ComponentStats {
    fn default() -> Self {
        Self {
            lo: [usize::MAX; 3],
            hi: [0; 3],
            sum_mm: DVec3::ZERO,
            count: 0,
            kidney_voxels: 0,
        }
    }
}

impl ComponentStats {
    fn add(&mut self, ijk: [usize; 3], world: DVec3, kidney: bool) {
        for (a, &v) in ijk.iter().enumerate() {
            self.lo[a] = self.lo[a].min(v);
            self.hi[a] = self.hi[a].max(v);
        }
        self.sum_mm += world;
        self.count += 1;
        self.kidney_voxels += kidney as usize;
    }

    fn centroid(&self) -> DVec3 {
        self.sum_mm / self.count.max(1) as f64
    }
}

/// Boundary areas of tumour component `t`: faces towards the organ (kidney, cyst, other
/// tumour of the same kidney) versus towards anything else.
fn exposure(
    block: &Block,
    bounds: &ComponentStats,
    tumour_id: &[u32],
    t: u32,
    organ_id: &[u32],
    organ: u32,
    face_area_mm2: [f64; 3],
) -> Exposure {
    let (mut exposed, mut enclosed) = (0.0, 0.0);
    let d = block.dims;
    for k in bounds.lo[2]..=bounds.hi[2] {
        for j in bounds.lo[1]..=bounds.hi[1] {
            for i in bounds.lo[0]..=bounds.hi[0] {
                let x = i + d[0] * (j + d[1] * k);
                if tumour_id[x] != t {
                    continue;
                }
                let steps: [(bool, usize, usize); 6] = [
                    (i > 0, x.wrapping_sub(1), 0),
                    (i + 1 < d[0], x + 1, 0),
                    (j > 0, x.wrapping_sub(d[0]), 1),
                    (j + 1 < d[1], x + d[0], 1),
                    (k > 0, x.wrapping_sub(d[0] * d[1]), 2),
                    (k + 1 < d[2], x + d[0] * d[1], 2),
                ];
                for (ok, m, axis) in steps {
                    if ok && tumour_id[m] == t {
                        continue;
                    }
                    if ok && organ_id[m] == organ {
                        enclosed += face_area_mm2[axis];
                    } else {
                        exposed += face_area_mm2[axis];
                    }
                }
            }
        }
    }
    let share = exposed / (exposed + enclosed).max(1e-12);
    Exposure {
        exposed_mm2: exposed,
        enclosed_mm2: enclosed,
        exposed_share: share,
        rule: format!(
            "visible (exophytic) when at least {:.0} % of the boundary area faces background; {:.1} % does",
            100.0 * EXPOSED_SHARE,
            100.0 * share
        ),
    }
}

/// Mask → checked, smoothed, decimated surface.
fn mesh_structure(
    name: &str,
    label: u8,
    visible: bool,
    m: Mask,
    vol: &LabelVolume,
    target_vertices: usize,
) -> Result<StructureReport, String> {
    let mut m = m.padded(2);
    let dropped = mask::keep_largest(&mut m);
    // The structure's own voxels, before cavities and repairs add any.
    let voxels = m.count();
    let mut added = mask::fill_cavities(&mut m);
    added += mask::make_well_composed(&mut m);
    let mut mesh = surface::extract(&m, vol);
    if mesh.faces.is_empty() {
        return Err(format!("{name}: the mask gives no surface"));
    }
    smooth::taubin(&mut mesh, SMOOTH_ITERATIONS);
    // Quadric collapses can pinch a thin part into an edge shared by four faces, or push a
    // face through a nearby sheet. Decimate in steps, each checked, and stop at the last valid
    // one: the result is always closed, manifold and free of intersections, at the cost of
    // more vertices than asked where the organ is thin. The dense surface is valid by
    // construction (a well-composed mask).
    let valid =
        |m: &Mesh| surface::topology(m).is_closed_manifold() && surface::self_intersections(m) == 0;
    let dense = mesh.clone();
    while mesh.vertices.len() > target_vertices + target_vertices / 50 {
        let n = mesh.vertices.len() as f64;
        let tries = [
            (0.7, false),
            (0.7, true),
            (0.85, false),
            (0.85, true),
            (0.95, false),
        ];
        let next = |ratio: f64| ((n * ratio) as usize).max(target_vertices);
        let step = tries.into_iter().find_map(|(ratio, regularize)| {
            let mut m = smooth::decimate(&mesh, next(ratio), regularize);
            smooth::taubin(&mut m, 1);
            (valid(&m) && m.vertices.len() < mesh.vertices.len()).then_some(m)
        });
        match step {
            Some(m) => mesh = m,
            None => break,
        }
    }
    // Stuck above the target: collapses in another order (straight from the dense surface,
    // to slightly different targets) often pass where the steps pinched.
    if mesh.vertices.len() > target_vertices + target_vertices / 10 {
        let stuck = mesh.vertices.len();
        for grow in [1.0, 1.05, 1.1, 1.2, 1.35] {
            let goal = (target_vertices as f64 * grow) as usize;
            let found = [false, true].into_iter().find_map(|regularize| {
                let mut m = smooth::decimate(&dense, goal, regularize);
                smooth::taubin(&mut m, 1);
                (valid(&m) && m.vertices.len() < mesh.vertices.len()).then_some(m)
            });
            if let Some(m) = found {
                mesh = m;
                break;
            }
        }
        log::debug!(
            "{name}: stepwise decimation stopped at {stuck} vertices; kept {}",
            mesh.vertices.len()
        );
    }
    let topology = surface::topology(&mesh);
    if !topology.is_closed_manifold() {
        return Err(format!(
            "{name}: the surface is not closed ({} open edges, {} non-manifold edges); please report this volume",
            topology.open_edges, topology.non_manifold_edges
        ));
    }
    let voxel_volume_mm3 = voxels as f64 * vol.voxel_volume_mm3();
    // What smoothing and decimation still took (surface nets cut voxel corners; a small
    // tumour of a few voxels' radius loses a few per cent): give it back by moving the surface
    // along its normals, by a fraction of a voxel at most, and keep the move only if the mesh
    // stays valid.
    let max_offset_mm = 0.5
        * vol
            .spacing_mm()
            .iter()
            .cloned()
            .fold(f64::INFINITY, f64::min);
    let mut normal_offset_mm = 0.0;
    let volume_before_offset_mm3 = mesh.signed_volume();
    let offset = smooth::volume_restoring_offset(&mesh, voxel_volume_mm3);
    if offset.abs() <= max_offset_mm {
        let moved = smooth::offset_along_normals(&mesh, offset);
        if valid(&moved) {
            mesh = moved;
            normal_offset_mm = offset;
        }
    }
    let self_intersections = surface::self_intersections(&mesh);
    let mesh_volume_mm3 = mesh.signed_volume();
    Ok(StructureReport {
        name: name.into(),
        label,
        visible,
        voxels,
        voxel_volume_mm3,
        mesh_volume_mm3,
        volume_error: (mesh_volume_mm3 - voxel_volume_mm3) / voxel_volume_mm3.max(1e-12),
        vertices: mesh.vertices.len(),
        faces: mesh.faces.len(),
        topology,
        self_intersections,
        voxels_added: added,
        voxels_dropped: dropped,
        normal_offset_mm,
        volume_error_before_offset: (volume_before_offset_mm3 - voxel_volume_mm3)
            / voxel_volume_mm3.max(1e-12),
        exposure: None,
        mesh,
    })
}

/// Which face of the volume a mask touches, if any (e.g. "i = 49").
fn touches_volume_edge(m: &Mask, dims: [usize; 3]) -> Option<String> {
    for (n, &inside) in m.data.iter().enumerate() {
        if !inside {
            continue;
        }
        let local = mask::unflatten(m.dims, n);
        for a in 0..3 {
            let v = local[a] as isize + m.origin[a];
            if v == 0 || v == dims[a] as isize - 1 {
                return Some(format!("{} = {v}", ["i", "j", "k"][a]));
            }
        }
    }
    None
}

/// The bounding block of some labels, as a window on the volume.
struct Block {
    dims: [usize; 3],
    origin: [usize; 3],
    volume_dims: [usize; 3],
}

impl Block {
    /// Block index `n` in the whole volume's voxels.
    fn global(&self, n: usize) -> [usize; 3] {
        let [i, j, k] = mask::unflatten(self.dims, n);
        [i + self.origin[0], j + self.origin[1], k + self.origin[2]]
    }

    fn volume_index(&self, n: usize) -> usize {
        let [i, j, k] = self.global(n);
        i + self.volume_dims[0] * (j + self.volume_dims[1] * k)
    }

    fn ijk(&self, n: usize) -> DVec3 {
        let [i, j, k] = self.global(n);
        DVec3::new(i as f64, j as f64, k as f64)
    }

    /// The mask of `inside` (block indices) over the bounds of one component only.
    fn mask_in(&self, b: &ComponentStats, inside: impl Fn(usize) -> bool) -> Mask {
        let dims = [0, 1, 2].map(|a| b.hi[a].saturating_sub(b.lo[a]) + 1);
        let origin = [0, 1, 2].map(|a| (self.origin[a] + b.lo[a].min(b.hi[a])) as isize);
        let mut m = Mask::new(dims, origin);
        let d = self.dims;
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let x = (b.lo[0] + i) + d[0] * ((b.lo[1] + j) + d[1] * (b.lo[2] + k));
                    let n = m.index(i, j, k);
                    m.data[n] = inside(x);
                }
            }
        }
        m
    }
}

fn bounding_block(vol: &LabelVolume, inside: impl Fn(u16) -> bool) -> Block {
    let mut lo = vol.dims;
    let mut hi = [0usize; 3];
    for k in 0..vol.dims[2] {
        for j in 0..vol.dims[1] {
            let row = vol.index(0, j, k);
            for i in 0..vol.dims[0] {
                if inside(vol.labels[row + i]) {
                    for (a, v) in [i, j, k].into_iter().enumerate() {
                        lo[a] = lo[a].min(v);
                        hi[a] = hi[a].max(v);
                    }
                }
            }
        }
    }
    let origin = [0, 1, 2].map(|a| lo[a].min(hi[a]));
    let dims = [0, 1, 2].map(|a| hi[a].saturating_sub(origin[a]) + 1);
    Block {
        dims,
        origin,
        volume_dims: vol.dims,
    }
}

/// What a user reads after `import-ct`: one line per structure.
pub fn summary(r: &ImportReport) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{}: {}×{}×{} voxels of {:.3}×{:.3}×{:.3} mm ({}); {} kidney(s); {} kidney ({})",
        r.source,
        r.dims[0],
        r.dims[1],
        r.dims[2],
        r.voxel_size_mm[0],
        r.voxel_size_mm[1],
        r.voxel_size_mm[2],
        format!("{:?}", r.world_transform).to_lowercase(),
        r.kidneys_found,
        r.side,
        r.side_reason
    );
    for st in &r.structures {
        let _ = writeln!(
            s,
            "  {:<14} label {:>2}  {:<7}  {:>5} vertices  voxels {:>9.0} mm³  mesh {:>9.0} mm³ ({:+.2} %){}",
            st.name,
            st.label,
            if st.visible { "visible" } else { "hidden" },
            st.vertices,
            st.voxel_volume_mm3,
            st.mesh_volume_mm3,
            100.0 * st.volume_error,
            st.exposure
                .as_ref()
                .map(|e| format!(
                    "  {:.1} % of its boundary faces background",
                    100.0 * e.exposed_share
                ))
                .unwrap_or_default()
        );
    }
    for n in &r.notes {
        let _ = writeln!(s, "  note: {n}");
    }
    s
}
