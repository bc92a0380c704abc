//! Reading and writing meshes: OBJ (every face flavour: `f a`, `f a/b`, `f a//c`, `f a/b/c`,
//! polygons triangulated), STL (ASCII and binary, with coincident vertices welded) and PLY
//! (ASCII and binary, either endianness; in `ply`). Every loaded mesh is validated; the
//! errors of [`load_mesh`] name the file.

mod ply;

pub use ply::{PlyError, parse_ply};

use super::mesh::{Mesh, MeshError};
use crate::error::InputError;
use glam::DVec3;
use std::collections::HashMap;
use std::io::Write;
use std::path::Path;

/// Why a mesh file could not be loaded: the file itself, its format, or the mesh it holds.
#[derive(Debug, thiserror::Error)]
pub enum MeshFileError {
    #[error("cannot read mesh: {0}")]
    Read(#[source] std::io::Error),
    /// The extension (lower case, without the dot) is none of obj, stl, ply.
    #[error("unknown mesh format '.{extension}' (expected .obj, .stl or .ply)")]
    UnknownFormat { extension: String },
    #[error(transparent)]
    Obj(#[from] ObjError),
    #[error(transparent)]
    Stl(#[from] StlError),
    #[error(transparent)]
    Ply(#[from] PlyError),
    #[error(transparent)]
    Invalid(#[from] MeshError),
}

/// A malformed OBJ. Line numbers count from 1, as editors show them.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ObjError {
    #[error("line {line}: malformed vertex")]
    MalformedVertex { line: usize },
    #[error("line {line}: a vertex needs 3 coordinates")]
    VertexArity { line: usize },
    #[error("line {line}: malformed face corner '{corner}'")]
    MalformedCorner { line: usize, corner: String },
    #[error("line {line}: face index 0 (OBJ indices start at 1)")]
    ZeroIndex { line: usize },
    /// `index` as written in the file (1-based, or negative for relative).
    #[error("line {line}: face index {index} is out of range")]
    IndexOutOfRange { line: usize, index: i64 },
    #[error("line {line}: a face needs at least 3 corners")]
    TooFewCorners { line: usize },
    #[error("OBJ holds no vertices (is it an OBJ file?)")]
    NoVertices,
}

/// A malformed STL (ASCII or binary). Line numbers count from 1.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StlError {
    #[error("ASCII STL is not valid text")]
    NotText,
    #[error("line {line}: malformed vertex")]
    MalformedVertex { line: usize },
    #[error("line {line}: a vertex needs 3 coordinates")]
    VertexArity { line: usize },
    #[error("line {line}: facet with {vertices} vertices (STL facets are triangles)")]
    FacetNotTriangle { line: usize, vertices: usize },
    #[error("binary STL shorter than its 84-byte header")]
    ShortHeader,
    #[error(
        "binary STL truncated: header promises {triangles} triangles ({needed_bytes} bytes), file has {file_bytes} bytes"
    )]
    Truncated {
        triangles: usize,
        needed_bytes: usize,
        file_bytes: usize,
    },
    #[error("STL holds no triangles")]
    NoTriangles,
}

/// Loads a mesh by its extension (.obj, .stl, .ply) and validates it.
pub fn load_mesh(path: &Path) -> Result<Mesh, InputError> {
    read_mesh(path).map_err(|e| InputError::new(path, e.to_string()))
}

/// [`load_mesh`] with the typed error, which does not name the file.
pub fn read_mesh(path: &Path) -> Result<Mesh, MeshFileError> {
    crate::error::regular_file(path).map_err(MeshFileError::Read)?;
    let bytes = std::fs::read(path).map_err(MeshFileError::Read)?;
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
        .unwrap_or_default();
    let mesh = match ext.as_str() {
        "obj" => parse_obj(&bytes)?,
        "stl" => parse_stl(&bytes)?,
        "ply" => parse_ply(&bytes)?,
        _ => return Err(MeshFileError::UnknownFormat { extension: ext }),
    };
    mesh.validate()?;
    Ok(mesh)
}

/// Reads the vertices (`v`) and faces (`f`) of an OBJ in file order. tobj re-indexes vertices
/// by first use, which would break the vertex correspondence shape catalogs rely on, so the
/// reader is our own; tests check it against tobj. Face corners may be `a`, `a/b`, `a//c` or
/// `a/b/c`, negative (relative) indices are resolved, polygons are fan-triangulated, and all
/// groups and objects are merged.
pub fn parse_obj(bytes: &[u8]) -> Result<Mesh, ObjError> {
    let text = String::from_utf8_lossy(bytes);
    let mut mesh = Mesh::default();
    let mut polygon: Vec<u32> = Vec::new();
    for (ln, line) in text.lines().enumerate() {
        let line_number = ln + 1;
        let line = line.split('#').next().unwrap_or("");
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => {
                let c: Vec<f64> = it
                    .take(3)
                    .map(|t| t.parse::<f64>())
                    .collect::<Result<_, _>>()
                    .map_err(|_| ObjError::MalformedVertex { line: line_number })?;
                if c.len() != 3 {
                    return Err(ObjError::VertexArity { line: line_number });
                }
                mesh.vertices.push(DVec3::new(c[0], c[1], c[2]));
            }
            Some("f") => {
                polygon.clear();
                for corner in it {
                    let first = corner.split('/').next().unwrap_or("");
                    let i: i64 = first.parse().map_err(|_| ObjError::MalformedCorner {
                        line: line_number,
                        corner: corner.to_string(),
                    })?;
                    let n = mesh.vertices.len() as i64;
                    let idx = match i {
                        0 => return Err(ObjError::ZeroIndex { line: line_number }),
                        i if i < 0 => n + i,
                        i => i - 1,
                    };
                    if idx < 0 || idx > u32::MAX as i64 {
                        return Err(ObjError::IndexOutOfRange {
                            line: line_number,
                            index: i,
                        });
                    }
                    polygon.push(idx as u32);
                }
                if polygon.len() < 3 {
                    return Err(ObjError::TooFewCorners { line: line_number });
                }
                for k in 1..polygon.len() - 1 {
                    mesh.faces.push([polygon[0], polygon[k], polygon[k + 1]]);
                }
            }
            _ => {}
        }
    }
    if mesh.vertices.is_empty() {
        return Err(ObjError::NoVertices);
    }
    Ok(mesh)
}

pub fn parse_stl(bytes: &[u8]) -> Result<Mesh, StlError> {
    let looks_ascii = bytes.starts_with(b"solid")
        && std::str::from_utf8(bytes)
            .map(|s| s.contains("facet"))
            .unwrap_or(false);
    let triangles = if looks_ascii {
        stl_ascii(bytes)?
    } else {
        stl_binary(bytes)?
    };
    if triangles.is_empty() {
        return Err(StlError::NoTriangles);
    }
    // STL repeats vertices per facet: weld exact duplicates, keeping first-seen order.
    let mut index: HashMap<[u64; 3], u32> = HashMap::new();
    let mut mesh = Mesh::default();
    for tri in triangles {
        let face = tri.map(|v| {
            let key = [v.x.to_bits(), v.y.to_bits(), v.z.to_bits()];
            *index.entry(key).or_insert_with(|| {
                mesh.vertices.push(v);
                (mesh.vertices.len() - 1) as u32
            })
        });
        mesh.faces.push(face);
    }
    Ok(mesh)
}

fn stl_ascii(bytes: &[u8]) -> Result<Vec<[DVec3; 3]>, StlError> {
    let text = std::str::from_utf8(bytes).map_err(|_| StlError::NotText)?;
    let mut tris = Vec::new();
    let mut current = Vec::with_capacity(3);
    for (ln, line) in text.lines().enumerate() {
        let line_number = ln + 1;
        let mut it = line.split_whitespace();
        match it.next() {
            Some("vertex") => {
                let c: Vec<f64> = it
                    .map(|t| t.parse::<f64>())
                    .collect::<Result<_, _>>()
                    .map_err(|_| StlError::MalformedVertex { line: line_number })?;
                if c.len() != 3 {
                    return Err(StlError::VertexArity { line: line_number });
                }
                current.push(DVec3::new(c[0], c[1], c[2]));
            }
            Some("endloop") => {
                if current.len() != 3 {
                    return Err(StlError::FacetNotTriangle {
                        line: line_number,
                        vertices: current.len(),
                    });
                }
                tris.push([current[0], current[1], current[2]]);
                current.clear();
            }
            _ => {}
        }
    }
    Ok(tris)
}

fn stl_binary(bytes: &[u8]) -> Result<Vec<[DVec3; 3]>, StlError> {
    if bytes.len() < 84 {
        return Err(StlError::ShortHeader);
    }
    let count = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as usize;
    let needed = 84 + count * 50;
    if bytes.len() < needed {
        return Err(StlError::Truncated {
            triangles: count,
            needed_bytes: needed,
            file_bytes: bytes.len(),
        });
    }
    let f =
        |o: usize| f32::from_le_bytes([bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]]) as f64;
    Ok((0..count)
        .map(|t| {
            let o = 84 + t * 50 + 12;
            [0, 1, 2].map(|k| DVec3::new(f(o + 12 * k), f(o + 12 * k + 4), f(o + 12 * k + 8)))
        })
        .collect())
}

/// Writes a mesh as OBJ (vertices with 6 decimals, 1-based triangle faces).
pub fn write_obj(path: &Path, mesh: &Mesh) -> std::io::Result<()> {
    let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
    out.write_all(obj_string(mesh).as_bytes())?;
    out.flush()
}

pub fn obj_string(mesh: &Mesh) -> String {
    use std::fmt::Write as _;
    let mut s = String::with_capacity(mesh.vertices.len() * 40 + mesh.faces.len() * 24);
    for v in &mesh.vertices {
        let _ = writeln!(s, "v {:.6} {:.6} {:.6}", v.x, v.y, v.z);
    }
    for f in &mesh.faces {
        let _ = writeln!(s, "f {} {} {}", f[0] + 1, f[1] + 1, f[2] + 1);
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    const CUBE_VERTS: &str =
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n";

    #[test]
    fn obj_face_flavours_agree() {
        let plain = format!("{CUBE_VERTS}f 1 2 3 4\nf 5 6 7 8\n");
        let with_normals =
            format!("{CUBE_VERTS}vn 0 0 1\nf 1//1 2//1 3//1 4//1\nf 5//1 6//1 7//1 8//1\n");
        let full = format!(
            "{CUBE_VERTS}vt 0 0\nvn 0 0 1\nf 1/1/1 2/1/1 3/1/1 4/1/1\nf 5/1/1 6/1/1 7/1/1 8/1/1\n"
        );
        let a = parse_obj(plain.as_bytes()).unwrap();
        let b = parse_obj(with_normals.as_bytes()).unwrap();
        let c = parse_obj(full.as_bytes()).unwrap();
        assert_eq!(a.faces.len(), 4, "quads are triangulated");
        assert_eq!(a.vertices, b.vertices);
        assert_eq!(a.faces, b.faces);
        assert_eq!(a.faces, c.faces);
        assert!(parse_obj(b"this is not an obj").is_err());
        assert!(
            parse_obj(b"v 0 0 0\nv 1 0 0\nf 1 2 0\n")
                .unwrap_err()
                .to_string()
                .contains("index 0")
        );
        let rel = parse_obj(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\n").unwrap();
        assert_eq!(rel.faces, vec![[0, 1, 2]]);
    }

    /// The same triangles (as coordinate triples) as tobj reads, on a real atlas mesh.
    #[test]
    fn obj_reader_agrees_with_tobj() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/fixtures/bodyparts3d_right_kidney.obj");
        let bytes = std::fs::read(&path).unwrap();
        let ours = parse_obj(&bytes).unwrap();
        let options = tobj::LoadOptions {
            triangulate: true,
            ..Default::default()
        };
        let (models, _) =
            tobj::load_obj_buf(&mut std::io::BufReader::new(&bytes[..]), &options, |_| {
                Ok(Default::default())
            })
            .unwrap();
        let key = |v: DVec3| [v.x as f32, v.y as f32, v.z as f32].map(f32::to_bits);
        let mut theirs: Vec<[[u32; 3]; 3]> = Vec::new();
        for m in &models {
            let p = &m.mesh.positions;
            for t in m.mesh.indices.chunks_exact(3) {
                theirs.push([t[0], t[1], t[2]].map(|i| {
                    [
                        p[3 * i as usize],
                        p[3 * i as usize + 1],
                        p[3 * i as usize + 2],
                    ]
                    .map(f32::to_bits)
                }));
            }
        }
        let mut mine: Vec<[[u32; 3]; 3]> = ours
            .faces
            .iter()
            .map(|f| f.map(|i| key(ours.vertices[i as usize])))
            .collect();
        theirs.sort();
        mine.sort();
        assert_eq!(mine.len(), 2478);
        assert_eq!(mine, theirs);
        assert!(ours.validate().is_ok(), "{:?}", ours.validate());
    }

    #[test]
    fn stl_ascii_and_binary_round_trip_with_welding() {
        let mesh = crate::geometry::mesh::icosphere(1);
        let mut ascii = String::from("solid t\n");
        let mut binary = vec![0u8; 80];
        binary.extend((mesh.faces.len() as u32).to_le_bytes());
        for f in &mesh.faces {
            ascii.push_str("facet normal 0 0 0\nouter loop\n");
            binary.extend([0u8; 12]);
            for &i in f {
                let v = mesh.vertices[i as usize].as_vec3();
                ascii.push_str(&format!("vertex {} {} {}\n", v.x, v.y, v.z));
                for c in [v.x, v.y, v.z] {
                    binary.extend(c.to_le_bytes());
                }
            }
            ascii.push_str("endloop\nendfacet\n");
            binary.extend([0u8; 2]);
        }
        ascii.push_str("endsolid t\n");
        let a = parse_stl(ascii.as_bytes()).unwrap();
        let b = parse_stl(&binary).unwrap();
        assert_eq!(
            a.vertices.len(),
            mesh.vertices.len(),
            "welded back to shared vertices"
        );
        assert_eq!(a.faces.len(), mesh.faces.len());
        assert_eq!(a.faces, b.faces);
        assert!(a.validate().is_ok());
        let truncated = &binary[..binary.len() - 10];
        assert!(
            parse_stl(truncated)
                .unwrap_err()
                .to_string()
                .contains("truncated")
        );
    }

    #[test]
    fn obj_write_read_round_trip() {
        let mesh = crate::geometry::mesh::icosphere(2);
        let back = parse_obj(obj_string(&mesh).as_bytes()).unwrap();
        assert_eq!(back.faces, mesh.faces);
        for (a, b) in back.vertices.iter().zip(&mesh.vertices) {
            assert!((*a - *b).length() < 1e-5);
        }
    }
}
