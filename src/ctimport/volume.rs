//! A CT label volume read from NIfTI-1 (`.nii`, `.nii.gz`) with the `nifti` crate: integer
//! labels on a voxel grid (index `i` fastest, as NIfTI stores it) and the voxel-to-world map in
//! millimetres. The map is the sform when its code is set, else the qform (quaternion, qfac),
//! else the pixdim diagonal — NIfTI's own precedence for "method 3, then 2, then 1". Any axis
//! order and orientation follow from that map; nothing assumes KiTS's layout.

use glam::{DMat3, DVec3};
use nifti::{NiftiObject, NiftiType, ReaderOptions};
use std::path::Path;

/// Which of the header's transforms gave world coordinates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum WorldTransform {
    Sform,
    Qform,
    Pixdim,
}

/// Integer labels on a 3D grid with its voxel-to-world map.
#[derive(Debug, Clone)]
pub struct LabelVolume {
    /// Voxels along i, j, k.
    pub dims: [usize; 3],
    /// Label of voxel (i, j, k) at `i + dims[0]·(j + dims[1]·k)`.
    pub labels: Vec<u16>,
    /// world = linear · (i, j, k) + offset, millimetres.
    pub linear: DMat3,
    pub offset_mm: DVec3,
    pub transform: WorldTransform,
    /// The NIfTI datatype as stored (for ct.json).
    pub datatype: String,
}

/// What can be wrong with a label volume file. The caller names the file.
#[derive(Debug, thiserror::Error)]
pub enum VolumeError {
    #[error("cannot read NIfTI ({0}); is the file complete and a .nii or .nii.gz?")]
    Read(String),
    #[error("not gzip data although the name ends in .gz")]
    NotGzip,
    #[error("a {0}-dimensional volume: a label map has 3 dimensions (a 4th of size 1 is allowed)")]
    Dimensions(usize),
    #[error(
        "datatype {0} cannot hold labels (uint8, int8, uint16, int16, int32, uint32, float32 or float64)"
    )]
    Datatype(String),
    #[error(
        "{count} voxels are not whole non-negative labels (e.g. {example}); is this a CT intensity image rather than a label map?"
    )]
    NotLabels { count: usize, example: f64 },
    #[error(
        "the voxel-to-world transform is degenerate (determinant {0:e}); check sform/qform/pixdim"
    )]
    Transform(f64),
    #[error(
        "a voxel step along {axis} of {mm:e} mm: a CT's lie between 0.001 and 100 mm; check the header's units, pixdim and sform/qform"
    )]
    VoxelSize { axis: &'static str, mm: f64 },
    #[error(
        "pixdim[{index}] is {value}, and the header gives no usable sform: the voxels' size is unknown (nifti1_io would take 1 mm and the meshes would come out the wrong size); write the CT with its spacing"
    )]
    NoSpacing { index: usize, value: f32 },
    #[error("the volume is empty (a dimension of size 0)")]
    Empty,
    #[error("dim[{index}] is {size}: a size cannot be negative (a broken header)")]
    NegativeSize { index: usize, size: i16 },
    #[error(
        "a header without voxels (the .hdr of a .hdr/.img pair): give a single-file .nii or .nii.gz"
    )]
    HeaderOnly,
}

impl LabelVolume {
    pub fn voxel_count(&self) -> usize {
        self.dims.iter().product()
    }

    pub fn index(&self, i: usize, j: usize, k: usize) -> usize {
        i + self.dims[0] * (j + self.dims[1] * k)
    }

    /// The labels other than 0 that occur, in increasing order.
    pub fn labels_present(&self) -> Vec<u16> {
        let mut seen = vec![false; 1 << 16];
        for &l in &self.labels {
            seen[l as usize] = true;
        }
        (1..seen.len())
            .filter(|&l| seen[l])
            .map(|l| l as u16)
            .collect()
    }

    /// Volume of one voxel, mm³.
    pub fn voxel_volume_mm3(&self) -> f64 {
        self.linear.determinant().abs()
    }

    /// Edge lengths of a voxel along i, j, k, mm.
    pub fn spacing_mm(&self) -> [f64; 3] {
        [
            self.linear.x_axis.length(),
            self.linear.y_axis.length(),
            self.linear.z_axis.length(),
        ]
    }

    /// World position of a (fractional) voxel index, mm.
    pub fn world(&self, ijk: DVec3) -> DVec3 {
        self.linear * ijk + self.offset_mm
    }
}

/// Reads a label volume. Gzip is recognised by its magic bytes, not only by the name.
pub fn read(path: &Path) -> Result<LabelVolume, VolumeError> {
    use std::io::BufRead;
    crate::error::regular_file(path).map_err(|e| VolumeError::Read(e.to_string()))?;
    let file = std::fs::File::open(path).map_err(|e| VolumeError::Read(e.to_string()))?;
    let mut source = std::io::BufReader::new(file);
    let gz = source
        .fill_buf()
        .map_err(|e| VolumeError::Read(e.to_string()))?
        .starts_with(&GZIP_MAGIC);
    check_gzip_name(path, gz)?;
    match decode(source, gz) {
        // A header-only file (the .hdr of a .hdr/.img pair): the crate finds the .img.
        Err(VolumeError::HeaderOnly) => {
            let obj = ReaderOptions::new()
                .read_file(path)
                .map_err(|e| VolumeError::Read(e.to_string()))?;
            let header = obj.header().clone();
            let raw = obj.into_volume().into_raw_data();
            from_header_and_voxels(&header, &raw)
        }
        other => other,
    }
}

/// [`read`] of a file's bytes already in memory, `name` standing for its path (the `.gz`
/// check). The fuzzer calls this: writing and re-reading a file per input was most of its time.
pub fn read_bytes(name: &Path, bytes: &[u8]) -> Result<LabelVolume, VolumeError> {
    let gz = bytes.starts_with(&GZIP_MAGIC);
    check_gzip_name(name, gz)?;
    decode(bytes, gz)
}

const GZIP_MAGIC: [u8; 2] = [0x1f, 0x8b];

fn check_gzip_name(path: &Path, gz: bool) -> Result<(), VolumeError> {
    let gz_name = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("gz"));
    if gz_name && !gz {
        return Err(VolumeError::NotGzip);
    }
    Ok(())
}

/// Header, then the voxels it describes. The voxel bytes are read as they come, never
/// reserved by the header's claim: a 40-byte file claiming 10⁹ voxels costs 40 bytes.
fn decode(source: impl std::io::Read, gz: bool) -> Result<LabelVolume, VolumeError> {
    if gz {
        return decode_plain(flate2::read::MultiGzDecoder::new(source));
    }
    decode_plain(source)
}

fn decode_plain(mut source: impl std::io::Read) -> Result<LabelVolume, VolumeError> {
    use std::io::Read;
    let read_err = |e: &dyn std::fmt::Display| VolumeError::Read(e.to_string());
    let header = nifti::NiftiHeader::from_reader(&mut source).map_err(header_error)?;
    if header.magic == *b"ni1\0" {
        return Err(VolumeError::HeaderOnly);
    }
    let (dims, datatype) = grid(&header)?;
    // The voxels start at vox_offset, after the 4-byte extender and any extensions (not
    // needed here). Below 352 (KiTS writes 0) they start right after the extender, as the
    // `nifti` crate and other readers take it.
    let start = (header.vox_offset as u64).max(FIRST_VOXEL_BYTE);
    let skip = start - HEADER_BYTES;
    std::io::copy(&mut (&mut source).take(skip), &mut std::io::sink()).map_err(|e| read_err(&e))?;
    let wanted = dims.iter().product::<usize>() * voxel_bytes(datatype)?;
    let mut raw = Vec::with_capacity(wanted.min(RESERVE_AT_MOST));
    source
        .take(wanted as u64)
        .read_to_end(&mut raw)
        .map_err(|e| read_err(&e))?;
    from_header_and_voxels(&header, &raw)
}

/// The header's read error in words (the crate's own text for an I/O error is Rust's debug
/// form: "Io(Custom { kind: UnexpectedEof, … })").
fn header_error(e: nifti::NiftiError) -> VolumeError {
    VolumeError::Read(match e {
        nifti::NiftiError::Io(io) if io.kind() == std::io::ErrorKind::UnexpectedEof => {
            "the data end inside the 348-byte header: truncated, or not a NIfTI file".into()
        }
        nifti::NiftiError::Io(io) => io.to_string(),
        nifti::NiftiError::InvalidFormat => {
            "no NIfTI-1 header (its magic is neither \"n+1\" nor \"ni1\")".into()
        }
        other => other.to_string(),
    })
}

const HEADER_BYTES: u64 = 348;
/// Header and extender: where voxels start at the earliest in a single file.
const FIRST_VOXEL_BYTE: u64 = 352;
/// What the header's claim may reserve up front; more grows as the bytes arrive.
const RESERVE_AT_MOST: usize = 16 << 20;

/// The grid's size and the datatype, refused when they cannot be a label map.
fn grid(header: &nifti::NiftiHeader) -> Result<([usize; 3], NiftiType), VolumeError> {
    // NIfTI-1 stores dim[] as signed 16-bit; the reader hands them over unsigned, so a
    // negative size read as 65,000-odd voxels (and a request for 17 GB of data).
    let signed = header.dim.map(|d| d as i16);
    let ndim = signed[0].max(0) as usize;
    if let Some((axis, &d)) = signed[1..=ndim.clamp(1, 7)]
        .iter()
        .enumerate()
        .find(|(_, d)| **d < 0)
    {
        return Err(VolumeError::NegativeSize {
            index: axis + 1,
            size: d,
        });
    }
    let dims_all: Vec<usize> = signed[1..=ndim.clamp(1, 7)]
        .iter()
        .map(|&d| d as usize)
        .collect();
    if !(3..=4).contains(&ndim) || (ndim == 4 && dims_all[3] != 1) {
        return Err(VolumeError::Dimensions(ndim));
    }
    let dims = [dims_all[0], dims_all[1], dims_all[2]];
    if dims.contains(&0) {
        return Err(VolumeError::Empty);
    }
    let datatype = header
        .data_type()
        .map_err(|e| VolumeError::Datatype(e.to_string()))?;
    voxel_bytes(datatype)?;
    Ok((dims, datatype))
}

fn from_header_and_voxels(
    header: &nifti::NiftiHeader,
    raw: &[u8],
) -> Result<LabelVolume, VolumeError> {
    let (dims, datatype) = grid(header)?;
    let big = header.endianness == nifti::Endianness::Big;
    let labels = decode_labels(raw, datatype, big, dims.iter().product())?;
    let (linear, offset_mm, transform) = world_map(header)?;
    let det = linear.determinant();
    if !det.is_finite() || det.abs() < 1e-9 {
        return Err(VolumeError::Transform(det));
    }
    // A CT's voxels measure from a few hundredths of a millimetre to a few millimetres: a step
    // outside 0.001–100 mm is a header in the wrong units or a broken one, whose meshes would
    // come out kilometres wide (or microscopic) without a word.
    for (axis, step) in ["i", "j", "k"].into_iter().zip(linear.to_cols_array_2d()) {
        let mm = DVec3::from_array(step).length();
        if !(1e-3..=100.0).contains(&mm) {
            return Err(VolumeError::VoxelSize { axis, mm });
        }
    }
    Ok(LabelVolume {
        dims,
        labels,
        linear,
        offset_mm,
        transform,
        datatype: format!("{datatype:?}").to_lowercase(),
    })
}

/// Bytes per voxel of the datatypes that can hold labels.
fn voxel_bytes(datatype: NiftiType) -> Result<usize, VolumeError> {
    Ok(match datatype {
        NiftiType::Uint8 | NiftiType::Int8 => 1,
        NiftiType::Uint16 | NiftiType::Int16 => 2,
        NiftiType::Int32 | NiftiType::Uint32 | NiftiType::Float32 => 4,
        NiftiType::Float64 => 8,
        other => return Err(VolumeError::Datatype(format!("{other:?}").to_lowercase())),
    })
}

/// Raw voxel bytes to labels. `scl_slope`/`scl_inter` are ignored on purpose: label maps
/// store labels, and KiTS files carry NaN there.
fn decode_labels(
    raw: &[u8],
    datatype: NiftiType,
    big_endian: bool,
    count: usize,
) -> Result<Vec<u16>, VolumeError> {
    let size = voxel_bytes(datatype)?;
    if raw.len() < count * size {
        return Err(VolumeError::Read(format!(
            "{} bytes of voxel data, the header says {}",
            raw.len(),
            count * size
        )));
    }
    let word = |b: &[u8]| -> u64 {
        let mut v = 0u64;
        for (n, &x) in b.iter().enumerate() {
            let shift = if big_endian {
                (b.len() - 1 - n) * 8
            } else {
                n * 8
            };
            v |= (x as u64) << shift;
        }
        v
    };
    let value = |b: &[u8]| -> f64 {
        let w = word(b);
        match datatype {
            NiftiType::Uint8 | NiftiType::Uint16 | NiftiType::Uint32 => w as f64,
            NiftiType::Int8 => w as u8 as i8 as f64,
            NiftiType::Int16 => w as u16 as i16 as f64,
            NiftiType::Int32 => w as u32 as i32 as f64,
            NiftiType::Float32 => f32::from_bits(w as u32) as f64,
            _ => f64::from_bits(w),
        }
    };
    let mut bad = 0usize;
    let mut example = 0.0;
    let labels = raw[..count * size]
        .chunks_exact(size)
        .map(|b| {
            let v = value(b);
            if v.is_finite() && v >= 0.0 && v <= u16::MAX as f64 && v.fract() == 0.0 {
                v as u16
            } else {
                if bad == 0 {
                    example = v;
                }
                bad += 1;
                0
            }
        })
        .collect();
    if bad > 0 {
        return Err(VolumeError::NotLabels {
            count: bad,
            example,
        });
    }
    Ok(labels)
}

/// Millimetres per unit of the header's spatial unit code (0 unknown: millimetres assumed).
fn unit_mm(xyzt_units: u8) -> f64 {
    match xyzt_units & 0x07 {
        1 => 1000.0,
        3 => 0.001,
        _ => 1.0,
    }
}

fn world_map(h: &nifti::NiftiHeader) -> Result<(DMat3, DVec3, WorldTransform), VolumeError> {
    let u = unit_mm(h.xyzt_units);
    let finite = |v: &[f32]| v.iter().all(|x| x.is_finite());
    if h.sform_code > 0 && finite(&h.srow_x) && finite(&h.srow_y) && finite(&h.srow_z) {
        let row = |r: &[f32; 4]| DVec3::new(r[0] as f64, r[1] as f64, r[2] as f64) * u;
        let (x, y, z) = (row(&h.srow_x), row(&h.srow_y), row(&h.srow_z));
        // Rows of the 3×3 part: columns are the world steps of i, j, k.
        let linear = DMat3::from_cols(
            DVec3::new(x.x, y.x, z.x),
            DVec3::new(x.y, y.y, z.y),
            DVec3::new(x.z, y.z, z.z),
        );
        let offset = DVec3::new(h.srow_x[3] as f64, h.srow_y[3] as f64, h.srow_z[3] as f64) * u;
        return Ok((linear, offset, WorldTransform::Sform));
    }
    // The qform and the bare pixdim both scale by pixdim[1..4]. nifti1_io takes 1 mm for a
    // zero or unreadable one; a CT read so gives meshes of the wrong size with no warning.
    let mut steps = [0.0; 3];
    for (n, step) in (1..4).zip(&mut steps) {
        let v = h.pixdim[n].abs() as f64;
        if !(v.is_finite() && v > 0.0) {
            return Err(VolumeError::NoSpacing {
                index: n,
                value: h.pixdim[n],
            });
        }
        *step = v * u;
    }
    let spacing = DMat3::from_diagonal(DVec3::from_array(steps));
    if h.qform_code > 0 {
        let (b, c, d) = (h.quatern_b as f64, h.quatern_c as f64, h.quatern_d as f64);
        // As nifti1_io.c's nifti_quatern_to_mat44: where b² + c² + d² reaches 1 (a header
        // that rounds, or a bad one), (b, c, d) is normalised and a = 0, a 180° turn; left as
        // it was, the matrix would not be a rotation and would scale the volume.
        let norm2 = b * b + c * c + d * d;
        let (a, b, c, d) = if 1.0 - norm2 < 1e-7 && norm2 > 0.0 {
            let n = norm2.sqrt();
            (0.0, b / n, c / n, d / n)
        } else {
            ((1.0 - norm2).max(0.0).sqrt(), b, c, d)
        };
        // NIfTI-1 qform rotation (nifti1.h, "METHOD 2").
        let r = DMat3::from_cols(
            DVec3::new(
                a * a + b * b - c * c - d * d,
                2.0 * (b * c + a * d),
                2.0 * (b * d - a * c),
            ),
            DVec3::new(
                2.0 * (b * c - a * d),
                a * a + c * c - b * b - d * d,
                2.0 * (c * d + a * b),
            ),
            DVec3::new(
                2.0 * (b * d + a * c),
                2.0 * (c * d - a * b),
                a * a + d * d - c * c - b * b,
            ),
        );
        let qfac = if h.pixdim[0] < 0.0 { -1.0 } else { 1.0 };
        let flip = DMat3::from_diagonal(DVec3::new(1.0, 1.0, qfac));
        let offset = DVec3::new(h.quatern_x as f64, h.quatern_y as f64, h.quatern_z as f64) * u;
        let offset = if offset.is_finite() {
            offset
        } else {
            DVec3::ZERO
        };
        return Ok((r * flip * spacing, offset, WorldTransform::Qform));
    }
    Ok((spacing, DVec3::ZERO, WorldTransform::Pixdim))
}

/// How [`write`] states the voxel-to-world map.
#[derive(Debug, Clone, Copy)]
pub enum WriteTransform {
    /// sform_code 2 with these rows.
    Sform,
    /// qform_code 1: quaternion (b, c, d), qfac, spacing and offset; no sform.
    Qform {
        quaternion_bcd: [f32; 3],
        qfac: f32,
        spacing_mm: [f32; 3],
        offset_mm: [f32; 3],
    },
    /// Neither: pixdim only.
    Pixdim { spacing_mm: [f32; 3] },
}

/// The datatypes [`write`] can store.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WriteType {
    Uint8,
    Int16,
    Uint16,
    Float32,
}

/// Writes a NIfTI-1 single file (`n+1`, 352-byte header) by hand, gzip when the name ends in
/// `.gz`, so that tests read files this module's reader did not write with the same library.
/// KiTS quirks are reproduced on request: `vox_offset` 0 and NaN scaling.
pub fn write(
    path: &Path,
    vol: &LabelVolume,
    transform: WriteTransform,
    datatype: WriteType,
    big_endian: bool,
) -> std::io::Result<()> {
    let mut h = vec![0u8; 352];
    let put = |h: &mut Vec<u8>, at: usize, bytes: &[u8]| {
        let b: Vec<u8> = if big_endian {
            bytes.iter().rev().copied().collect()
        } else {
            bytes.to_vec()
        };
        h[at..at + b.len()].copy_from_slice(&b);
    };
    put(&mut h, 0, &348i32.to_le_bytes());
    let dim = [
        3i16,
        vol.dims[0] as i16,
        vol.dims[1] as i16,
        vol.dims[2] as i16,
        1,
        1,
        1,
        1,
    ];
    for (n, d) in dim.iter().enumerate() {
        put(&mut h, 40 + 2 * n, &d.to_le_bytes());
    }
    let (code, bitpix): (i16, i16) = match datatype {
        WriteType::Uint8 => (2, 8),
        WriteType::Int16 => (4, 16),
        WriteType::Uint16 => (512, 16),
        WriteType::Float32 => (16, 32),
    };
    put(&mut h, 70, &code.to_le_bytes());
    put(&mut h, 72, &bitpix.to_le_bytes());
    let s = vol.spacing_mm();
    let mut pixdim = [
        1.0f32,
        s[0] as f32,
        s[1] as f32,
        s[2] as f32,
        1.0,
        1.0,
        1.0,
        1.0,
    ];
    match transform {
        WriteTransform::Qform {
            qfac, spacing_mm, ..
        } => {
            pixdim[0] = qfac;
            pixdim[1..4].copy_from_slice(&spacing_mm);
        }
        WriteTransform::Pixdim { spacing_mm } => pixdim[1..4].copy_from_slice(&spacing_mm),
        WriteTransform::Sform => {}
    }
    for (n, p) in pixdim.iter().enumerate() {
        put(&mut h, 76 + 4 * n, &p.to_le_bytes());
    }
    // KiTS writes vox_offset 0 and NaN scaling; readers must cope.
    put(&mut h, 108, &0f32.to_le_bytes());
    put(&mut h, 112, &f32::NAN.to_le_bytes());
    put(&mut h, 116, &f32::NAN.to_le_bytes());
    h[123] = 2; // millimetres
    match transform {
        WriteTransform::Sform => {
            put(&mut h, 254, &2i16.to_le_bytes());
            let l = vol.linear;
            let o = vol.offset_mm;
            let rows = [
                [l.x_axis.x, l.y_axis.x, l.z_axis.x, o.x],
                [l.x_axis.y, l.y_axis.y, l.z_axis.y, o.y],
                [l.x_axis.z, l.y_axis.z, l.z_axis.z, o.z],
            ];
            for (r, row) in rows.iter().enumerate() {
                for (c, v) in row.iter().enumerate() {
                    put(&mut h, 280 + 16 * r + 4 * c, &(*v as f32).to_le_bytes());
                }
            }
        }
        WriteTransform::Qform {
            quaternion_bcd,
            offset_mm,
            ..
        } => {
            put(&mut h, 252, &1i16.to_le_bytes());
            for (n, v) in quaternion_bcd.iter().chain(offset_mm.iter()).enumerate() {
                put(&mut h, 256 + 4 * n, &v.to_le_bytes());
            }
        }
        WriteTransform::Pixdim { .. } => {}
    }
    h[344..348].copy_from_slice(b"n+1\0");
    for &v in &vol.labels {
        match datatype {
            WriteType::Uint8 => h.push(v.min(255) as u8),
            WriteType::Int16 => {
                let b = (v as i16).to_le_bytes();
                h.extend(if big_endian { [b[1], b[0]] } else { b });
            }
            WriteType::Uint16 => {
                let b = v.to_le_bytes();
                h.extend(if big_endian { [b[1], b[0]] } else { b });
            }
            WriteType::Float32 => {
                let mut b = (v as f32).to_le_bytes();
                if big_endian {
                    b.reverse();
                }
                h.extend(b);
            }
        }
    }
    if path.extension().is_some_and(|e| e == "gz") {
        use std::io::Write;
        let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        enc.write_all(&h)?;
        h = enc.finish()?;
    }
    std::fs::write(path, h)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The same grid written with a sform and with the equivalent qform (a rotation and
    /// qfac = −1) reads back to the same world map, and labels survive each datatype.
    #[test]
    fn sform_and_qform_agree_and_labels_round_trip() {
        let dir = std::env::temp_dir().join(format!("endofuse-nifti-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let rot = glam::DQuat::from_axis_angle(DVec3::new(1.0, 2.0, -0.5).normalize(), 0.7);
        let r = DMat3::from_quat(rot);
        let spacing = DVec3::new(0.9, 1.1, 2.5);
        // qfac = −1 flips k before rotating.
        let linear = r * DMat3::from_diagonal(DVec3::new(spacing.x, spacing.y, -spacing.z));
        let offset = DVec3::new(-12.0, 40.0, 7.5);
        let vol = LabelVolume {
            dims: [5, 4, 3],
            labels: (0..60).map(|n| (n % 4) as u16).collect(),
            linear,
            offset_mm: offset,
            transform: WorldTransform::Sform,
            datatype: String::new(),
        };
        let q = if rot.w < 0.0 { -rot } else { rot };
        let cases = [
            ("s.nii", WriteTransform::Sform, WriteType::Uint8, false),
            ("s.nii.gz", WriteTransform::Sform, WriteType::Int16, true),
            ("f.nii", WriteTransform::Sform, WriteType::Float32, true),
            (
                "q.nii.gz",
                WriteTransform::Qform {
                    quaternion_bcd: [q.x as f32, q.y as f32, q.z as f32],
                    qfac: -1.0,
                    spacing_mm: spacing.to_array().map(|v| v as f32),
                    offset_mm: offset.to_array().map(|v| v as f32),
                },
                WriteType::Uint16,
                false,
            ),
        ];
        for (name, t, ty, big) in cases {
            let p = dir.join(name);
            write(&p, &vol, t, ty, big).unwrap();
            let back = read(&p).unwrap();
            assert_eq!(back.labels, vol.labels, "{name}");
            assert_eq!(back.dims, vol.dims);
            for ijk in [
                DVec3::ZERO,
                DVec3::new(4.0, 3.0, 2.0),
                DVec3::new(1.0, 0.0, 2.0),
            ] {
                let d = (back.world(ijk) - vol.world(ijk)).length();
                assert!(d < 1e-4, "{name}: voxel {ijk} is {d} mm off");
            }
        }
        let p = dir.join("p.nii");
        write(
            &p,
            &vol,
            WriteTransform::Pixdim {
                spacing_mm: [0.5, 0.6, 0.7],
            },
            WriteType::Uint8,
            false,
        )
        .unwrap();
        let back = read(&p).unwrap();
        assert_eq!(back.transform, WorldTransform::Pixdim);
        assert!((back.voxel_volume_mm3() - 0.5 * 0.6 * 0.7).abs() < 1e-6);

        // A qform whose (b, c, d) is not inside the unit ball is normalised as nifti1_io.c
        // does (a 180° turn): the voxels keep their size instead of growing with |(b, c, d)|.
        let p = dir.join("q-bad.nii");
        write(
            &p,
            &vol,
            WriteTransform::Qform {
                quaternion_bcd: [2.0, 2.0, 2.0],
                qfac: 1.0,
                spacing_mm: [2.0, 2.0, 2.0],
                offset_mm: [0.0; 3],
            },
            WriteType::Uint8,
            false,
        )
        .unwrap();
        let back = read(&p).unwrap();
        assert!((back.voxel_volume_mm3() - 8.0).abs() < 1e-6);
        for col in back.linear.to_cols_array_2d() {
            assert!((DVec3::from_array(col).length() - 2.0).abs() < 1e-6);
        }
        // Voxels a kilometre wide are a broken header, said as such.
        let p = dir.join("huge.nii");
        write(
            &p,
            &vol,
            WriteTransform::Pixdim {
                spacing_mm: [1e6, 1.0, 1.0],
            },
            WriteType::Uint8,
            false,
        )
        .unwrap();
        let err = read(&p).unwrap_err().to_string();
        assert!(err.contains("voxel step along i"), "{err}");
        // A zero or unreadable pixdim with no sform is an unknown voxel size, not 1 mm (the
        // qform scales by pixdim as well).
        for (name, spacing, bad) in [
            ("zero.nii", [1.0, 0.0, 1.0], "pixdim[2] is 0"),
            ("nan.nii", [f32::NAN, 1.0, 1.0], "pixdim[1] is NaN"),
        ] {
            let p = dir.join(name);
            write(
                &p,
                &vol,
                WriteTransform::Pixdim {
                    spacing_mm: spacing,
                },
                WriteType::Uint8,
                false,
            )
            .unwrap();
            let err = read(&p).unwrap_err().to_string();
            assert!(
                err.contains(bad) && err.contains("size is unknown"),
                "{err}"
            );
            let p = dir.join(format!("q-{name}"));
            write(
                &p,
                &vol,
                WriteTransform::Qform {
                    quaternion_bcd: [0.0; 3],
                    qfac: 1.0,
                    spacing_mm: spacing,
                    offset_mm: [0.0; 3],
                },
                WriteType::Uint8,
                false,
            )
            .unwrap();
            let err = read(&p).unwrap_err().to_string();
            assert!(err.contains(bad), "{err}");
        }
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// Where the voxels start: after the extender when vox_offset is below 352 (KiTS writes
    /// 0), at vox_offset otherwise (extensions skipped); bytes in memory read as the file
    /// does; gzip found by its magic under a plain name; a header that claims more voxels
    /// than the data hold is refused with both counts.
    #[test]
    fn voxel_offset_extensions_bytes_and_lying_headers() {
        let dir = std::env::temp_dir().join(format!("endofuse-nifti-off-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let vol = LabelVolume {
            dims: [3, 2, 2],
            labels: (0..12).map(|n| (n % 5) as u16).collect(),
            linear: DMat3::IDENTITY,
            offset_mm: DVec3::ZERO,
            transform: WorldTransform::Sform,
            datatype: String::new(),
        };
        let p = dir.join("v.nii");
        write(&p, &vol, WriteTransform::Sform, WriteType::Uint8, false).unwrap();
        let kits = std::fs::read(&p).unwrap();
        assert_eq!(
            read_bytes(&p, &kits).unwrap().labels,
            vol.labels,
            "vox_offset 0"
        );
        let mut at_352 = kits.clone();
        at_352[108..112].copy_from_slice(&352f32.to_le_bytes());
        assert_eq!(
            read_bytes(&p, &at_352).unwrap().labels,
            vol.labels,
            "vox_offset 352"
        );
        // An extension of 16 bytes (flagged in the extender) before the voxels.
        let mut with_ext = at_352[..348].to_vec();
        with_ext[108..112].copy_from_slice(&368f32.to_le_bytes());
        with_ext.extend_from_slice(&[1, 0, 0, 0]);
        with_ext.extend_from_slice(&16i32.to_le_bytes());
        with_ext.extend_from_slice(&4i32.to_le_bytes());
        with_ext.extend_from_slice(&[7u8; 8]);
        with_ext.extend_from_slice(&at_352[352..]);
        assert_eq!(
            read_bytes(&p, &with_ext).unwrap().labels,
            vol.labels,
            "extension"
        );
        std::fs::write(&p, &with_ext).unwrap();
        assert_eq!(
            read(&p).unwrap().labels,
            vol.labels,
            "extension, from the file"
        );

        let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        std::io::Write::write_all(&mut gz, &kits).unwrap();
        let gz = gz.finish().unwrap();
        std::fs::write(&p, &gz).unwrap();
        assert_eq!(read(&p).unwrap().labels, vol.labels, "gzip named .nii");
        assert!(matches!(
            read_bytes(Path::new("v.nii.gz"), &kits),
            Err(VolumeError::NotGzip)
        ));

        // 1000 x 1000 x 1000 voxels claimed, 12 present.
        let mut lying = kits.clone();
        for (n, d) in [1000u16, 1000, 1000].iter().enumerate() {
            lying[42 + 2 * n..44 + 2 * n].copy_from_slice(&d.to_le_bytes());
        }
        let e = read_bytes(&p, &lying).unwrap_err().to_string();
        assert!(
            e.contains("12 bytes of voxel data, the header says 1000000000"),
            "{e}"
        );
        // A negative size (dim[] is signed) is said as such, not as 65,531 voxels.
        let mut negative = kits.clone();
        negative[44..46].copy_from_slice(&(-5i16).to_le_bytes());
        let e = read_bytes(&p, &negative).unwrap_err().to_string();
        assert!(e.contains("dim[2] is -5"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
