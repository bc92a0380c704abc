//! ffprobe, twice: once for the first video stream's size, codec, rates and time base, once for
//! its packet list (timestamps and keyframe flags, read without decoding), from which the
//! frame table is built. The container's frame count is not asked for: headers can be wrong
//! or missing, the packets are what a decoder will see.

use super::timeline::{Packet, Timeline};
use super::tools::{StderrCollector, first_line, input_url, spawn_error};
use super::{Tools, VideoError, VideoInfo};
use serde::Deserialize;
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};

/// What opening a video needs: its description and its frame table.
pub(crate) struct Probed {
    pub info: VideoInfo,
    pub timeline: Timeline,
    /// The stream has B-frames (decode order is not display order).
    pub reorders: bool,
}

#[derive(Deserialize)]
struct ProbeJson {
    #[serde(default)]
    streams: Vec<StreamJson>,
    format: Option<FormatJson>,
}

#[derive(Deserialize)]
struct StreamJson {
    codec_name: Option<String>,
    width: Option<u32>,
    height: Option<u32>,
    avg_frame_rate: Option<String>,
    r_frame_rate: Option<String>,
    time_base: Option<String>,
    has_b_frames: Option<u32>,
}

#[derive(Deserialize)]
struct FormatJson {
    start_time: Option<String>,
    format_name: Option<String>,
}

/// The first video stream that is not cover art: `V`, not `v`, in FFmpeg's stream specifiers.
pub(crate) const VIDEO_STREAM: &str = "V:0";

pub(crate) fn probe(path: &Path, tools: &Tools) -> Result<Probed, VideoError> {
    let unreadable = |message: String| VideoError::Unreadable {
        path: path.to_path_buf(),
        message,
    };
    match std::fs::metadata(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Err(VideoError::NotFound {
                path: path.to_path_buf(),
            });
        }
        Err(e) => return Err(unreadable(e.to_string())),
        Ok(m) if m.is_dir() => return Err(unreadable("a folder, not a video file".into())),
        // ffprobe would wait on a pipe for ever.
        Ok(m) if !m.is_file() => {
            return Err(unreadable(
                "not a regular file (a pipe or a device): give the video file itself".into(),
            ));
        }
        Ok(_) => {}
    }
    let (stream, origin, avi) = stream_info(path, tools)?;
    let (width, height) = match (stream.width, stream.height) {
        (Some(w), Some(h)) if w > 0 && h > 0 => (w, h),
        _ => return Err(unreadable("the video stream has no frame size".into())),
    };
    let time_base = stream
        .time_base
        .as_deref()
        .and_then(ratio)
        .ok_or_else(|| unreadable("the video stream has no time base".into()))?;
    let packets = packets(path, tools)?;
    if packets.is_empty() {
        return Err(VideoError::NoFrames {
            path: path.to_path_buf(),
        });
    }
    let timeline = Timeline::from_packets(&packets, time_base, origin, avi).map_err(unreadable)?;
    let fps = [&stream.avg_frame_rate, &stream.r_frame_rate]
        .into_iter()
        .find_map(|r| r.as_deref().and_then(ratio))
        .unwrap_or(1.0 / timeline.mean_interval());
    let info = VideoInfo {
        width,
        height,
        frame_count: timeline.len(),
        fps,
        codec: stream.codec_name.unwrap_or_else(|| "unknown".into()),
        start_time: timeline.time(0).unwrap_or(0.0),
    };
    Ok(Probed {
        info,
        timeline,
        reorders: stream.has_b_frames.unwrap_or(0) > 0,
    })
}

/// The first video stream's description, the container's start time (`-ss` counts from it)
/// and whether the container is AVI.
fn stream_info(path: &Path, tools: &Tools) -> Result<(StreamJson, f64, bool), VideoError> {
    let out = Command::new(&tools.ffprobe)
        .args([
            "-v",
            "error",
            "-select_streams",
            VIDEO_STREAM,
            "-show_entries",
        ])
        .arg(
            "stream=codec_name,width,height,avg_frame_rate,r_frame_rate,time_base,has_b_frames\
             :format=start_time,format_name",
        )
        .args(["-of", "json"])
        .arg(input_url(path))
        .stdin(Stdio::null())
        .output()
        .map_err(|e| spawn_error(&tools.ffprobe, path, e))?;
    if !out.status.success() {
        return Err(VideoError::Unreadable {
            path: path.to_path_buf(),
            message: first_line(&out.stderr, path)
                .unwrap_or_else(|| format!("ffprobe exited with {}", out.status)),
        });
    }
    let parsed: ProbeJson = serde_json::from_slice(&out.stdout).map_err(|e| VideoError::Tool {
        path: path.to_path_buf(),
        program: tools.ffprobe.display().to_string(),
        message: format!("unexpected output: {e}"),
    })?;
    let format = parsed.format.unwrap_or(FormatJson {
        start_time: None,
        format_name: None,
    });
    let origin = format
        .start_time
        .and_then(|s| s.parse::<f64>().ok())
        .filter(|s| s.is_finite())
        .unwrap_or(0.0);
    let avi = format
        .format_name
        .is_some_and(|n| n.split(',').any(|n| n == "avi"));
    match parsed.streams.into_iter().next() {
        Some(stream) => Ok((stream, origin, avi)),
        None => Err(VideoError::NoVideoStream {
            path: path.to_path_buf(),
        }),
    }
}

/// The video stream's packets in decode order, read line by line (a long video lists hundreds
/// of thousands).
fn packets(path: &Path, tools: &Tools) -> Result<Vec<Packet>, VideoError> {
    let mut child = Command::new(&tools.ffprobe)
        .args(["-v", "error", "-select_streams", VIDEO_STREAM])
        .args(["-show_entries", "packet=pts,dts,flags", "-of", "csv=p=0"])
        .arg(input_url(path))
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| spawn_error(&tools.ffprobe, path, e))?;
    let mut stderr = StderrCollector::start(child.stderr.take());
    let mut packets = Vec::new();
    let mut bad_line = None;
    if let Some(stdout) = child.stdout.take() {
        for line in BufReader::new(stdout).lines() {
            let Ok(line) = line else { break };
            let line = line.trim();
            if line.is_empty() {
                continue;
            }
            match parse_packet(line) {
                Some(p) => packets.push(p),
                None => {
                    bad_line = Some(line.to_string());
                    break;
                }
            }
        }
    }
    // A bad line ends the reading early: stop ffprobe rather than wait for it.
    if bad_line.is_some() {
        let _ = child.kill();
    }
    let status = child.wait();
    let errors = stderr.finish();
    if let Some(line) = bad_line {
        return Err(VideoError::Tool {
            path: path.to_path_buf(),
            program: tools.ffprobe.display().to_string(),
            message: format!("unexpected packet line {line:?}"),
        });
    }
    let ok = status.as_ref().is_ok_and(|s| s.success());
    let message = first_line(&errors, path);
    if !ok && packets.is_empty() {
        return Err(VideoError::Unreadable {
            path: path.to_path_buf(),
            message: message.unwrap_or_else(|| "ffprobe could not list the packets".into()),
        });
    }
    if let Some(m) = message {
        // A truncated file lists the packets that are there; the decoder will tell which of
        // them cannot be decoded.
        log::warn!("{}: {m}", path.display());
    }
    Ok(packets)
}

/// `pts,dts,flags` as ffprobe's CSV writes it, e.g. `1536,-512,__` or `N/A,0,K_`.
fn parse_packet(line: &str) -> Option<Packet> {
    let mut fields = line.split(',');
    let stamp = |f: Option<&str>| -> Option<Option<i64>> {
        match f?.trim() {
            "N/A" | "" => Some(None),
            v => v.parse().ok().map(Some),
        }
    };
    let pts = stamp(fields.next())?;
    let dts = stamp(fields.next())?;
    let flags = fields.next()?.trim();
    Some(Packet {
        pts,
        dts,
        key: flags.starts_with('K'),
        discard: flags.contains('D'),
    })
}

/// `30000/1001` → 29.97; `0/0` and other non-rates → `None`.
fn ratio(text: &str) -> Option<f64> {
    let (n, d) = text.split_once('/').unwrap_or((text, "1"));
    let (n, d) = (n.trim().parse::<f64>().ok()?, d.trim().parse::<f64>().ok()?);
    let r = n / d;
    (r.is_finite() && r > 0.0).then_some(r)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packet_lines() {
        assert_eq!(
            parse_packet("1536,-512,__"),
            Some(Packet {
                pts: Some(1536),
                dts: Some(-512),
                key: false,
                discard: false
            })
        );
        let p = parse_packet("N/A,7,K_D").unwrap();
        assert_eq!(
            (p.pts, p.dts, p.key, p.discard),
            (None, Some(7), true, true)
        );
        // ffprobe 6 and later print a third flag (C: corrupt).
        assert!(parse_packet("0,0,K__").unwrap().key);
        assert_eq!(parse_packet("side_data"), None);
        assert_eq!(parse_packet("1,2"), None);
        assert_eq!(parse_packet("x,2,K_"), None);
    }

    #[test]
    fn rates() {
        assert_eq!(ratio("30/1"), Some(30.0));
        assert!((ratio("30000/1001").unwrap() - 29.97).abs() < 1e-3);
        assert_eq!(ratio("1/15360"), Some(1.0 / 15360.0));
        assert_eq!(ratio("0/0"), None);
        assert_eq!(ratio("25"), Some(25.0));
        assert_eq!(ratio("abc"), None);
    }

    #[test]
    fn missing_file_and_folder() {
        let tools = Tools::default();
        let missing = Path::new("/nonexistent/endofuse/video.mp4");
        assert!(matches!(
            probe(missing, &tools),
            Err(VideoError::NotFound { .. })
        ));
        let dir = std::env::temp_dir();
        assert!(matches!(
            probe(&dir, &tools),
            Err(VideoError::Unreadable { .. })
        ));
    }
}
