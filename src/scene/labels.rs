//! Label PNGs (8-bit grey): ground truth, seeds and output masks. Reading accepts 8-bit grey,
//! or RGB(A) whose channels are equal (some painting tools save that); anything else is an
//! error naming the file.

use crate::error::InputError;
use crate::plane::{LabelImage, Plane};
use image::{DynamicImage, GrayImage};
use std::path::Path;

pub fn read_label_png(path: &Path) -> Result<LabelImage, InputError> {
    read_label_png_sized(path, |_, _| Ok(()))
}

/// [`read_label_png`] whose size (width, height), read from the header, `check` accepts
/// before any pixel is decoded: a small file claiming a huge image costs nothing.
pub fn read_label_png_sized(
    path: &Path,
    check: impl FnOnce(usize, usize) -> Result<(), InputError>,
) -> Result<LabelImage, InputError> {
    let reader = image::ImageReader::open(path)
        .map_err(|e| InputError::new(path, format!("cannot open label image: {e}")))?;
    decode_label_image(path, reader, check)
}

/// [`read_label_png_sized`] of bytes already in memory; `path` names them in errors. (The
/// fuzzer calls this: a file written and read back per input would be most of its time.)
pub fn decode_label_png(
    path: &Path,
    bytes: &[u8],
    check: impl FnOnce(usize, usize) -> Result<(), InputError>,
) -> Result<LabelImage, InputError> {
    decode_label_image(
        path,
        image::ImageReader::new(std::io::Cursor::new(bytes)),
        check,
    )
}

fn decode_label_image<R: std::io::BufRead + std::io::Seek>(
    path: &Path,
    reader: image::ImageReader<R>,
    check: impl FnOnce(usize, usize) -> Result<(), InputError>,
) -> Result<LabelImage, InputError> {
    use image::ImageDecoder;
    let decoder = reader
        .with_guessed_format()
        .map_err(|e| InputError::new(path, format!("cannot read label image: {e}")))?
        .into_decoder()
        .map_err(|e| InputError::new(path, format!("cannot decode label image: {e}")))?;
    let (w, h) = decoder.dimensions();
    check(w as usize, h as usize)?;
    let img = DynamicImage::from_decoder(decoder)
        .map_err(|e| InputError::new(path, format!("cannot decode label image: {e}")))?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    let data = match img {
        DynamicImage::ImageLuma8(g) => g.into_raw(),
        DynamicImage::ImageLumaA8(g) => g.pixels().map(|p| p.0[0]).collect(),
        DynamicImage::ImageRgb8(rgb) => {
            grey_from_channels(path, rgb.pixels().map(|p| [p.0[0], p.0[1], p.0[2]]))?
        }
        DynamicImage::ImageRgba8(rgba) => {
            grey_from_channels(path, rgba.pixels().map(|p| [p.0[0], p.0[1], p.0[2]]))?
        }
        other => {
            return Err(InputError::new(
                path,
                format!("label image must be 8-bit grey, found {:?}", other.color()),
            ));
        }
    };
    Ok(Plane {
        width: w,
        height: h,
        data,
    })
}

fn grey_from_channels(
    path: &Path,
    pixels: impl Iterator<Item = [u8; 3]>,
) -> Result<Vec<u8>, InputError> {
    pixels
        .map(|[r, g, b]| {
            if r == g && g == b {
                Ok(r)
            } else {
                Err(InputError::new(
                    path,
                    "label image has colours; it must be 8-bit grey with one label value per pixel",
                ))
            }
        })
        .collect()
}

/// Writes an 8-bit grey PNG, creating parent folders.
pub fn write_label_png(path: &Path, labels: &LabelImage) -> std::io::Result<()> {
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent)?;
    }
    let img = GrayImage::from_raw(
        labels.width as u32,
        labels.height as u32,
        labels.data.clone(),
    )
    .ok_or_else(|| std::io::Error::other("label buffer size does not match its dimensions"))?;
    super::write::save_image(path, &img)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_refusals() {
        let dir = std::env::temp_dir().join(format!("endofuse-labels-{}", std::process::id()));
        let p = dir.join("a/b.png");
        let img = Plane::from_vec(3, 2, vec![0, 1, 2, 255, 3, 0]).unwrap();
        write_label_png(&p, &img).unwrap();
        assert_eq!(read_label_png(&p).unwrap(), img);
        let rgb = dir.join("rgb.png");
        image::RgbImage::from_fn(2, 2, |x, _| image::Rgb([x as u8, 0, 0]))
            .save(&rgb)
            .unwrap();
        assert!(
            read_label_png(&rgb)
                .unwrap_err()
                .problem
                .contains("colours")
        );
        let junk = dir.join("junk.png");
        std::fs::write(&junk, b"\x89PNG\r\n\x1a\nnot really").unwrap();
        assert!(read_label_png(&junk).is_err());
        assert!(read_label_png(&dir.join("missing.png")).is_err());

        // The size check sees the header's size and runs before the pixels are decoded: a
        // PNG whose pixel data are cut off still gets the check's answer.
        let bytes = std::fs::read(&p).unwrap();
        let cut = &bytes[..bytes.len() - 16]; // IEND and the pixel data's end cut off
        let mut seen = None;
        let e = decode_label_png(&p, cut, |w, h| {
            seen = Some((w, h));
            Err(InputError::new(&p, "not this camera's size"))
        })
        .unwrap_err();
        assert_eq!(seen, Some((3, 2)));
        assert_eq!(e.problem, "not this camera's size");
        assert!(decode_label_png(&p, cut, |_, _| Ok(())).is_err());
        assert_eq!(decode_label_png(&p, &bytes, |_, _| Ok(())).unwrap(), img);
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A full disk is an error, not an empty file reported as written (`image`'s `save`
    /// dropped the failed flush of its buffered writer).
    #[cfg(target_os = "linux")]
    #[test]
    fn a_png_written_to_a_full_disk_is_an_error() {
        let dir = std::env::temp_dir().join(format!("endofuse-full-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let full = dir.join("full.png");
        let _ = std::fs::remove_file(&full);
        std::os::unix::fs::symlink("/dev/full", &full).unwrap();
        let img = Plane::from_vec(3, 2, vec![0, 1, 2, 255, 3, 0]).unwrap();
        let err = write_label_png(&full, &img).unwrap_err();
        assert_eq!(err.raw_os_error(), Some(28), "ENOSPC, not {err}");
        let rgb = image::RgbImage::from_pixel(4, 4, image::Rgb([9, 9, 9]));
        assert!(crate::scene::write::write_rgb(&full, &rgb).is_err());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
