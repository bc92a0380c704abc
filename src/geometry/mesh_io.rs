//! Reading and writing meshes: OBJ (through tobj, every face flavour: `f a`, `f a/b`,
//! `f a//c`, `f a/b/c`, polygons triangulated), STL (ASCII and binary, with coincident
//! vertices welded) and PLY (ASCII and binary, either endianness). Every loaded mesh is
//! validated; errors name the file.

use super::mesh::Mesh;
use crate::error::InputError;
use glam::DVec3;
use std::collections::HashMap;
use std::io::Write;
use std::path::Path;

/// Loads a mesh by its extension (.obj, .stl, .ply) and validates it.
pub fn load_mesh(path: &Path) -> Result<Mesh, InputError> {
    let bytes =
        std::fs::read(path).map_err(|e| InputError::new(path, format!("cannot read mesh: {e}")))?;
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
        .unwrap_or_default();
    let mesh = match ext.as_str() {
        "obj" => parse_obj(&bytes),
        "stl" => parse_stl(&bytes),
        "ply" => parse_ply(&bytes),
        other => Err(format!(
            "unknown mesh format '.{other}' (expected .obj, .stl or .ply)"
        )),
    }
    .map_err(|p| InputError::new(path, p))?;
    mesh.validate().map_err(|p| InputError::new(path, p))?;
    Ok(mesh)
}

/// Reads the vertices (`v`) and faces (`f`) of an OBJ in file order. tobj re-indexes vertices
/// by first use, which would break the vertex correspondence shape catalogs rely on, so the
/// reader is our own; tests check it against tobj. Face corners may be `a`, `a/b`, `a//c` or
/// `a/b/c`, negative (relative) indices are resolved, polygons are fan-triangulated, and all
/// groups and objects are merged.
pub fn parse_obj(bytes: &[u8]) -> Result<Mesh, String> {
    let text = String::from_utf8_lossy(bytes);
    let mut mesh = Mesh::default();
    let mut polygon: Vec<u32> = Vec::new();
    for (ln, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("");
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => {
                let c: Vec<f64> = it
                    .take(3)
                    .map(|t| t.parse::<f64>())
                    .collect::<Result<_, _>>()
                    .map_err(|_| format!("line {}: malformed vertex", ln + 1))?;
                if c.len() != 3 {
                    return Err(format!("line {}: a vertex needs 3 coordinates", ln + 1));
                }
                mesh.vertices.push(DVec3::new(c[0], c[1], c[2]));
            }
            Some("f") => {
                polygon.clear();
                for corner in it {
                    let first = corner.split('/').next().unwrap_or("");
                    let i: i64 = first.parse().map_err(|_| {
                        format!("line {}: malformed face corner '{corner}'", ln + 1)
                    })?;
                    let n = mesh.vertices.len() as i64;
                    let idx = match i {
                        0 => {
                            return Err(format!(
                                "line {}: face index 0 (OBJ indices start at 1)",
                                ln + 1
                            ));
                        }
                        i if i < 0 => n + i,
                        i => i - 1,
                    };
                    if idx < 0 || idx > u32::MAX as i64 {
                        return Err(format!("line {}: face index {i} is out of range", ln + 1));
                    }
                    polygon.push(idx as u32);
                }
                if polygon.len() < 3 {
                    return Err(format!("line {}: a face needs at least 3 corners", ln + 1));
                }
                for k in 1..polygon.len() - 1 {
                    mesh.faces.push([polygon[0], polygon[k], polygon[k + 1]]);
                }
            }
            _ => {}
        }
    }
    if mesh.vertices.is_empty() {
        return Err("OBJ holds no vertices (is it an OBJ file?)".into());
    }
    Ok(mesh)
}

pub fn parse_stl(bytes: &[u8]) -> Result<Mesh, String> {
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
        return Err("STL holds no triangles".into());
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

fn stl_ascii(bytes: &[u8]) -> Result<Vec<[DVec3; 3]>, String> {
    let text = std::str::from_utf8(bytes).map_err(|_| "ASCII STL is not valid text".to_string())?;
    let mut tris = Vec::new();
    let mut current = Vec::with_capacity(3);
    for (ln, line) in text.lines().enumerate() {
        let mut it = line.split_whitespace();
        match it.next() {
            Some("vertex") => {
                let c: Vec<f64> = it
                    .map(|t| t.parse::<f64>())
                    .collect::<Result<_, _>>()
                    .map_err(|_| format!("line {}: malformed vertex", ln + 1))?;
                if c.len() != 3 {
                    return Err(format!("line {}: a vertex needs 3 coordinates", ln + 1));
                }
                current.push(DVec3::new(c[0], c[1], c[2]));
            }
            Some("endloop") => {
                if current.len() != 3 {
                    return Err(format!(
                        "line {}: facet with {} vertices (STL facets are triangles)",
                        ln + 1,
                        current.len()
                    ));
                }
                tris.push([current[0], current[1], current[2]]);
                current.clear();
            }
            _ => {}
        }
    }
    Ok(tris)
}

fn stl_binary(bytes: &[u8]) -> Result<Vec<[DVec3; 3]>, String> {
    if bytes.len() < 84 {
        return Err("binary STL shorter than its 84-byte header".into());
    }
    let count = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as usize;
    let needed = 84 + count * 50;
    if bytes.len() < needed {
        return Err(format!(
            "binary STL truncated: header promises {count} triangles ({needed} bytes), file has {} bytes",
            bytes.len()
        ));
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

#[derive(Clone, Copy, PartialEq)]
enum PlyFormat {
    Ascii,
    BinaryLe,
    BinaryBe,
}

#[derive(Clone, Copy)]
enum PlyType {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl PlyType {
    fn parse(name: &str) -> Option<Self> {
        Some(match name {
            "char" | "int8" => Self::I8,
            "uchar" | "uint8" => Self::U8,
            "short" | "int16" => Self::I16,
            "ushort" | "uint16" => Self::U16,
            "int" | "int32" => Self::I32,
            "uint" | "uint32" => Self::U32,
            "float" | "float32" => Self::F32,
            "double" | "float64" => Self::F64,
            _ => return None,
        })
    }
    fn size(self) -> usize {
        match self {
            Self::I8 | Self::U8 => 1,
            Self::I16 | Self::U16 => 2,
            Self::I32 | Self::U32 | Self::F32 => 4,
            Self::F64 => 8,
        }
    }
}

enum PlyProperty {
    Scalar(String, PlyType),
    List(String, PlyType, PlyType),
}

struct PlyElement {
    name: String,
    count: usize,
    properties: Vec<PlyProperty>,
}

/// Reads PLY values one at a time from either the ASCII token stream or the binary bytes.
struct PlyReader<'a> {
    format: PlyFormat,
    bytes: &'a [u8],
    pos: usize,
    tokens: std::str::SplitAsciiWhitespace<'a>,
}

impl PlyReader<'_> {
    fn read(&mut self, t: PlyType) -> Result<f64, String> {
        if self.format == PlyFormat::Ascii {
            let tok = self
                .tokens
                .next()
                .ok_or("PLY data ends early (truncated file?)")?;
            return tok
                .parse::<f64>()
                .map_err(|_| format!("PLY value '{tok}' is not a number"));
        }
        let n = t.size();
        let raw = self
            .bytes
            .get(self.pos..self.pos + n)
            .ok_or("PLY data ends early (truncated file?)")?;
        self.pos += n;
        let mut b = [0u8; 8];
        b[..n].copy_from_slice(raw);
        if self.format == PlyFormat::BinaryBe {
            b[..n].reverse();
        }
        Ok(match t {
            PlyType::I8 => b[0] as i8 as f64,
            PlyType::U8 => b[0] as f64,
            PlyType::I16 => i16::from_le_bytes([b[0], b[1]]) as f64,
            PlyType::U16 => u16::from_le_bytes([b[0], b[1]]) as f64,
            PlyType::I32 => i32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            PlyType::U32 => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            PlyType::F32 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            PlyType::F64 => f64::from_le_bytes(b),
        })
    }
}

pub fn parse_ply(bytes: &[u8]) -> Result<Mesh, String> {
    let header_end = bytes
        .windows(10)
        .position(|w| w == b"end_header")
        .ok_or("not a PLY file (no end_header)")?;
    let header = std::str::from_utf8(&bytes[..header_end]).map_err(|_| "PLY header is not text")?;
    let mut body_start = header_end + 10;
    while body_start < bytes.len() && bytes[body_start] != b'\n' {
        body_start += 1;
    }
    body_start += 1;
    let mut lines = header.lines();
    if lines.next().map(str::trim) != Some("ply") {
        return Err("not a PLY file (first line is not 'ply')".into());
    }
    let mut format = None;
    let mut elements: Vec<PlyElement> = Vec::new();
    for line in lines {
        let t: Vec<&str> = line.split_whitespace().collect();
        match t.as_slice() {
            ["format", f, _] => {
                format = Some(match *f {
                    "ascii" => PlyFormat::Ascii,
                    "binary_little_endian" => PlyFormat::BinaryLe,
                    "binary_big_endian" => PlyFormat::BinaryBe,
                    other => return Err(format!("unknown PLY format '{other}'")),
                })
            }
            ["element", name, count] => elements.push(PlyElement {
                name: name.to_string(),
                count: count
                    .parse()
                    .map_err(|_| format!("PLY element '{name}' has a bad count"))?,
                properties: Vec::new(),
            }),
            ["property", "list", ct, it, name] => {
                let el = elements
                    .last_mut()
                    .ok_or("PLY property before any element")?;
                let (c, i) = (PlyType::parse(ct), PlyType::parse(it));
                el.properties.push(PlyProperty::List(
                    name.to_string(),
                    c.ok_or(format!("unknown PLY type '{ct}'"))?,
                    i.ok_or(format!("unknown PLY type '{it}'"))?,
                ));
            }
            ["property", ty, name] => {
                let el = elements
                    .last_mut()
                    .ok_or("PLY property before any element")?;
                el.properties.push(PlyProperty::Scalar(
                    name.to_string(),
                    PlyType::parse(ty).ok_or(format!("unknown PLY type '{ty}'"))?,
                ));
            }
            _ => {}
        }
    }
    let format = format.ok_or("PLY header has no format line")?;
    let body = bytes.get(body_start..).unwrap_or(&[]);
    let text = if format == PlyFormat::Ascii {
        std::str::from_utf8(body).map_err(|_| "ASCII PLY body is not text")?
    } else {
        ""
    };
    let mut reader = PlyReader {
        format,
        bytes: body,
        pos: 0,
        tokens: text.split_ascii_whitespace(),
    };
    let mut mesh = Mesh::default();
    for el in &elements {
        for _ in 0..el.count {
            let mut xyz = [f64::NAN; 3];
            for prop in &el.properties {
                match prop {
                    PlyProperty::Scalar(name, t) => {
                        let v = reader.read(*t)?;
                        if el.name == "vertex" {
                            match name.as_str() {
                                "x" => xyz[0] = v,
                                "y" => xyz[1] = v,
                                "z" => xyz[2] = v,
                                _ => {}
                            }
                        }
                    }
                    PlyProperty::List(name, ct, it) => {
                        let n = reader.read(*ct)?;
                        if !(0.0..=1e6).contains(&n) {
                            return Err(format!("PLY list of bad length {n}"));
                        }
                        let idx: Vec<f64> = (0..n as usize)
                            .map(|_| reader.read(*it))
                            .collect::<Result<_, _>>()?;
                        if el.name == "face" && (name == "vertex_indices" || name == "vertex_index")
                        {
                            if idx.len() < 3 {
                                return Err(format!(
                                    "PLY face {} has fewer than 3 vertices",
                                    mesh.faces.len() + 1
                                ));
                            }
                            if idx.iter().any(|&i| i < 0.0 || i > u32::MAX as f64) {
                                return Err(format!(
                                    "PLY face {} has a negative index",
                                    mesh.faces.len() + 1
                                ));
                            }
                            // Fan-triangulate polygons.
                            for k in 1..idx.len() - 1 {
                                mesh.faces
                                    .push([idx[0] as u32, idx[k] as u32, idx[k + 1] as u32]);
                            }
                        }
                    }
                }
            }
            if el.name == "vertex" {
                if xyz.iter().any(|v| v.is_nan())
                    && !el
                        .properties
                        .iter()
                        .any(|p| matches!(p, PlyProperty::Scalar(n, _) if n == "x"))
                {
                    return Err("PLY vertex element has no x/y/z properties".into());
                }
                mesh.vertices.push(DVec3::from_array(xyz));
            }
        }
    }
    Ok(mesh)
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
        assert!(parse_stl(truncated).unwrap_err().contains("truncated"));
    }

    #[test]
    fn ply_ascii_and_binary() {
        let ascii = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n0 0 0 9\n1 0 0 9\n1 1 0 9\n0 1 0 9\n3 0 1 2\n3 0 2 3\n";
        let a = parse_ply(ascii.as_bytes()).unwrap();
        assert_eq!(a.vertices.len(), 4);
        assert_eq!(a.faces, vec![[0, 1, 2], [0, 2, 3]]);
        let mut bin = b"ply\nformat binary_big_endian 1.0\nelement vertex 4\nproperty double x\nproperty double y\nproperty double z\nelement face 1\nproperty list uchar uint vertex_index\nend_header\n".to_vec();
        for v in &a.vertices {
            for c in [v.x, v.y, v.z] {
                bin.extend(c.to_be_bytes());
            }
        }
        bin.push(4);
        for i in [0u32, 1, 2, 3] {
            bin.extend(i.to_be_bytes());
        }
        let b = parse_ply(&bin).unwrap();
        assert_eq!(b.vertices, a.vertices);
        assert_eq!(b.faces, a.faces, "quad fan-triangulated");
        assert!(
            parse_ply(&bin[..bin.len() - 3])
                .unwrap_err()
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
