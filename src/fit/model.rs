//! The fitted model's geometry: the joint shape instance for weights W (eq. 1), posed by the
//! global affine T (eq. 2), and each structure's edge–face adjacency, from which the rim
//! (silhouette-generating edges) is found for any camera.

use crate::error::InputError;
use crate::geometry::{Affine, Mesh};
use crate::render::RenderObject;
use crate::scene::Scene;
use crate::shape::JointShapeModel;
use glam::DVec3;
use std::collections::HashMap;
use std::sync::Arc;

/// An edge with the two faces that share it (the second may be missing on open meshes).
#[derive(Debug, Clone, Copy)]
pub struct Edge {
    pub a: u32,
    pub b: u32,
    pub faces: [u32; 2],
    pub boundary: bool,
}

/// What the fit needs of one structure.
#[derive(Debug, Clone)]
pub struct StructureModel {
    pub name: String,
    pub label: u8,
    pub visible: bool,
    pub faces: Vec<[u32; 3]>,
    pub edges: Vec<Edge>,
    /// Every edge shared by exactly two faces (rasters may cull its back faces).
    pub closed: bool,
    /// Index into the joint shape model's parts.
    pub part: usize,
}

/// All structures and their joint shape model.
#[derive(Debug, Clone)]
pub struct Model {
    pub structures: Vec<StructureModel>,
    pub shape: JointShapeModel,
    /// The structure whose weights name the joint vector in outputs (the organ).
    pub anchor: usize,
    /// The last few shape instances made, by their weights: a frame's steps, lines, priors
    /// and information ask for the same weights again and again, and the instance (every
    /// vertex times every mode) was the largest cost of a Gauss–Newton step.
    instances: InstanceCache,
}

/// Every structure's deformed vertices: one shape instance.
pub type Instance = Arc<Vec<Vec<DVec3>>>;

/// Recent shape instances keyed by their weights' bits (so a hit is the very same instance).
#[derive(Debug, Default)]
struct InstanceCache(std::sync::Mutex<Vec<(Vec<u64>, Instance)>>);

/// Instances kept: a step alternates between the state's and a trial's.
const INSTANCES_KEPT: usize = 4;

impl Clone for InstanceCache {
    fn clone(&self) -> Self {
        Self::default()
    }
}

impl Model {
    /// The model of a scene's structures: their meshes' adjacency and the joint shape model
    /// built from their catalogs (generated when none is given: a few hundred ms, so build it
    /// once per scene and share it). An error names the scene.
    pub fn build(scene: &Scene) -> Result<Self, InputError> {
        let shape = crate::shape::joint_model_of(&scene.structures)
            .map_err(|e| InputError::new(&scene.origin, format!("shape model: {e}")))?;
        Ok(Self::with_shape(scene, shape))
    }

    /// The model of a scene's structures with a joint shape model already built for them.
    pub fn with_shape(scene: &Scene, shape: JointShapeModel) -> Self {
        let structures = scene
            .structures
            .iter()
            .enumerate()
            .map(|(i, s)| StructureModel {
                name: s.name.clone(),
                label: s.label,
                visible: s.visible,
                faces: s.mesh.faces.clone(),
                closed: is_closed(&s.mesh.faces),
                edges: edges(&s.mesh),
                part: i,
            })
            .collect();
        let anchor = anchor_index(&scene.structures);
        Self {
            structures,
            shape,
            anchor,
            instances: InstanceCache::default(),
        }
    }

    /// Deformed preoperative vertices of every structure for weights `w` (shared: the same
    /// weights give the same instance without computing it again).
    pub fn deformed(&self, w: &[f64]) -> Instance {
        let key: Vec<u64> = w.iter().map(|v| v.to_bits()).collect();
        let cached = |cache: &[(Vec<u64>, Instance)]| {
            cache
                .iter()
                .find(|(k, _)| *k == key)
                .map(|(_, v)| v.clone())
        };
        if let Ok(cache) = self.instances.0.lock()
            && let Some(hit) = cached(&cache)
        {
            return hit;
        }
        let made = Arc::new(self.shape.instance(w));
        if let Ok(mut cache) = self.instances.0.lock() {
            if cache.len() >= INSTANCES_KEPT {
                cache.remove(0);
            }
            cache.push((key, made.clone()));
        }
        made
    }

    /// Render objects for the structures `which`, from their posed vertices.
    pub fn objects<'a>(
        &'a self,
        posed: &'a [Vec<DVec3>],
        which: &[usize],
    ) -> Vec<RenderObject<'a>> {
        which
            .iter()
            .map(|&i| RenderObject {
                vertices: &posed[i],
                faces: &self.structures[i].faces,
                closed: self.structures[i].closed,
            })
            .collect()
    }

    /// Indices of the visible (or hidden) structures.
    pub fn indices(&self, visible: bool) -> Vec<usize> {
        (0..self.structures.len())
            .filter(|&i| self.structures[i].visible == visible)
            .collect()
    }

    /// Vertices in camera-0 coordinates.
    pub fn posed(&self, affine: &Affine, deformed: &[Vec<DVec3>]) -> Vec<Vec<DVec3>> {
        deformed
            .iter()
            .map(|v| v.iter().map(|&p| affine.apply(p)).collect())
            .collect()
    }
}

/// Whether every undirected edge of `faces` belongs to exactly two of them, once each way
/// (closed, edge-manifold and consistently wound).
pub fn is_closed(faces: &[[u32; 3]]) -> bool {
    let mut directed: std::collections::HashMap<(u32, u32), u32> = Default::default();
    for f in faces {
        for k in 0..3 {
            *directed.entry((f[k], f[(k + 1) % 3])).or_default() += 1;
        }
    }
    !faces.is_empty()
        && directed
            .iter()
            .all(|(&(a, b), &n)| n == 1 && directed.get(&(b, a)) == Some(&1))
}

fn edges(mesh: &Mesh) -> Vec<Edge> {
    let mut map: HashMap<(u32, u32), usize> = HashMap::new();
    let mut out: Vec<Edge> = Vec::new();
    for (fi, f) in mesh.faces.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (f[k], f[(k + 1) % 3]);
            let key = (a.min(b), a.max(b));
            match map.get(&key) {
                Some(&e) if out[e].boundary => {
                    out[e].faces[1] = fi as u32;
                    out[e].boundary = false;
                }
                Some(_) => {}
                None => {
                    map.insert(key, out.len());
                    out.push(Edge {
                        a: key.0,
                        b: key.1,
                        faces: [fi as u32, fi as u32],
                        boundary: true,
                    });
                }
            }
        }
    }
    out
}

/// The structure whose shape weights name the joint model in outputs: the visible one with
/// the most vertices (the organ).
pub fn anchor_index(structures: &[crate::scene::Structure]) -> usize {
    structures
        .iter()
        .enumerate()
        .filter(|(_, s)| s.visible)
        .max_by_key(|(_, s)| s.mesh.vertices.len())
        .map(|(i, _)| i)
        .unwrap_or(0)
}
