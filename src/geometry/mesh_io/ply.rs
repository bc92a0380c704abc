//! PLY meshes: the header (format, elements and their scalar or list properties) and the body
//! in ASCII or binary of either endianness. Only the vertex x/y/z and the face vertex indices
//! are kept; other properties are read past so that any exporter's files load.

use crate::geometry::mesh::Mesh;
use glam::DVec3;

/// A malformed PLY header or body.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlyError {
    #[error("not a PLY file (no end_header)")]
    NoEndHeader,
    #[error("PLY header is not text")]
    HeaderNotText,
    #[error("not a PLY file (first line is not 'ply')")]
    NoMagic,
    #[error("unknown PLY format '{format}'")]
    UnknownFormat { format: String },
    #[error("PLY element '{element}' has a bad count")]
    BadCount { element: String },
    #[error("PLY property before any element")]
    PropertyBeforeElement,
    #[error("unknown PLY type '{type_name}'")]
    UnknownType { type_name: String },
    #[error("PLY header has no format line")]
    NoFormat,
    #[error("ASCII PLY body is not text")]
    BodyNotText,
    #[error("PLY data ends early (truncated file?)")]
    Truncated,
    #[error("PLY value '{token}' is not a number")]
    NotANumber { token: String },
    /// `length` as read: negative, fractional or above a million.
    #[error("PLY list of bad length {length}")]
    BadListLength { length: f64 },
    /// `face` is the number of triangles read before this face: the PLY face's index as long
    /// as earlier faces were triangles (polygons are fan-triangulated as they are read).
    #[error("PLY face {} has fewer than 3 vertices", .face + 1)]
    TooFewCorners { face: usize },
    /// A vertex index below 0 or above u32::MAX; the message predates the upper bound.
    #[error("PLY face {} has a negative index", .face + 1)]
    IndexOutOfRange { face: usize },
    #[error("PLY vertex element has no x/y/z properties")]
    NoCoordinates,
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
    fn read(&mut self, t: PlyType) -> Result<f64, PlyError> {
        if self.format == PlyFormat::Ascii {
            let tok = self.tokens.next().ok_or(PlyError::Truncated)?;
            return tok.parse::<f64>().map_err(|_| PlyError::NotANumber {
                token: tok.to_string(),
            });
        }
        let n = t.size();
        let raw = self
            .bytes
            .get(self.pos..self.pos + n)
            .ok_or(PlyError::Truncated)?;
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

pub fn parse_ply(bytes: &[u8]) -> Result<Mesh, PlyError> {
    let header_end = bytes
        .windows(10)
        .position(|w| w == b"end_header")
        .ok_or(PlyError::NoEndHeader)?;
    let header = std::str::from_utf8(&bytes[..header_end]).map_err(|_| PlyError::HeaderNotText)?;
    let mut body_start = header_end + 10;
    while body_start < bytes.len() && bytes[body_start] != b'\n' {
        body_start += 1;
    }
    body_start += 1;
    let mut lines = header.lines();
    if lines.next().map(str::trim) != Some("ply") {
        return Err(PlyError::NoMagic);
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
                    other => {
                        return Err(PlyError::UnknownFormat {
                            format: other.to_string(),
                        });
                    }
                })
            }
            ["element", name, count] => elements.push(PlyElement {
                name: name.to_string(),
                count: count.parse().map_err(|_| PlyError::BadCount {
                    element: name.to_string(),
                })?,
                properties: Vec::new(),
            }),
            ["property", "list", ct, it, name] => {
                let el = elements.last_mut().ok_or(PlyError::PropertyBeforeElement)?;
                el.properties.push(PlyProperty::List(
                    name.to_string(),
                    ply_type(ct)?,
                    ply_type(it)?,
                ));
            }
            ["property", ty, name] => {
                let el = elements.last_mut().ok_or(PlyError::PropertyBeforeElement)?;
                el.properties
                    .push(PlyProperty::Scalar(name.to_string(), ply_type(ty)?));
            }
            _ => {}
        }
    }
    let format = format.ok_or(PlyError::NoFormat)?;
    let body = bytes.get(body_start..).unwrap_or(&[]);
    let text = if format == PlyFormat::Ascii {
        std::str::from_utf8(body).map_err(|_| PlyError::BodyNotText)?
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
        // An element without properties holds no data, whatever count its header claims
        // (walking a claimed 10¹¹ of them was a hang the fuzzer found).
        if el.properties.is_empty() {
            if el.name == "vertex" && el.count > 0 {
                return Err(PlyError::NoCoordinates);
            }
            continue;
        }
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
                            return Err(PlyError::BadListLength { length: n });
                        }
                        let idx: Vec<f64> = (0..n as usize)
                            .map(|_| reader.read(*it))
                            .collect::<Result<_, _>>()?;
                        if el.name == "face" && (name == "vertex_indices" || name == "vertex_index")
                        {
                            if idx.len() < 3 {
                                return Err(PlyError::TooFewCorners {
                                    face: mesh.faces.len(),
                                });
                            }
                            if idx.iter().any(|&i| i < 0.0 || i > u32::MAX as f64) {
                                return Err(PlyError::IndexOutOfRange {
                                    face: mesh.faces.len(),
                                });
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
                    return Err(PlyError::NoCoordinates);
                }
                mesh.vertices.push(DVec3::from_array(xyz));
            }
        }
    }
    Ok(mesh)
}

fn ply_type(name: &str) -> Result<PlyType, PlyError> {
    PlyType::parse(name).ok_or_else(|| PlyError::UnknownType {
        type_name: name.to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

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
                .to_string()
                .contains("truncated")
        );
    }
}
