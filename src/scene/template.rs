//! Path templates of scene.json: `{frame}`, `{frame:06}` (zero-padded width), `{camera}` and
//! `{structure}`. Parsed once, so a typo is reported at load time, not mid-run.

#[derive(Debug, Clone, PartialEq, Eq)]
enum Piece {
    Text(String),
    Frame { width: usize },
    Camera,
    Structure,
}

/// Why a path template cannot be used; each variant carries the template as written.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TemplateError {
    #[error("template '{template}' has an unclosed '{{'")]
    Unclosed { template: String },
    /// `spec` is what follows `frame:`, which must be a zero and a width, like `06`.
    #[error("template '{template}': frame format '{spec}' should look like 06")]
    FrameFormat { template: String, spec: String },
    /// `placeholder` is the text between the braces.
    #[error(
        "template '{template}' has an unknown placeholder '{{{placeholder}}}' (known: frame, camera, structure)"
    )]
    UnknownPlaceholder {
        template: String,
        placeholder: String,
    },
}

/// A parsed path template.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PathTemplate {
    source: String,
    pieces: Vec<Piece>,
}

impl PathTemplate {
    pub fn parse(source: &str) -> Result<Self, TemplateError> {
        let mut pieces = Vec::new();
        let mut rest = source;
        while let Some(open) = rest.find('{') {
            if open > 0 {
                pieces.push(Piece::Text(rest[..open].to_string()));
            }
            let close = rest[open..]
                .find('}')
                .ok_or_else(|| TemplateError::Unclosed {
                    template: source.to_string(),
                })?
                + open;
            let inner = &rest[open + 1..close];
            let (name, spec) = inner.split_once(':').unwrap_or((inner, ""));
            pieces.push(match name {
                "frame" => {
                    let width = if spec.is_empty() {
                        0
                    } else {
                        spec.trim_start_matches('0')
                            .parse::<usize>()
                            .ok()
                            .filter(|w| *w <= 12 && spec.starts_with('0'))
                            .ok_or_else(|| TemplateError::FrameFormat {
                                template: source.to_string(),
                                spec: spec.to_string(),
                            })?
                    };
                    Piece::Frame { width }
                }
                "camera" if spec.is_empty() => Piece::Camera,
                "structure" if spec.is_empty() => Piece::Structure,
                _ => {
                    return Err(TemplateError::UnknownPlaceholder {
                        template: source.to_string(),
                        placeholder: inner.to_string(),
                    });
                }
            });
            rest = &rest[close + 1..];
        }
        if !rest.is_empty() {
            pieces.push(Piece::Text(rest.to_string()));
        }
        Ok(Self {
            source: source.to_string(),
            pieces,
        })
    }

    pub fn uses_frame(&self) -> bool {
        self.pieces.iter().any(|p| matches!(p, Piece::Frame { .. }))
    }

    pub fn source(&self) -> &str {
        &self.source
    }

    pub fn expand(&self, frame: usize, camera: &str, structure: &str) -> String {
        let mut s = String::new();
        for p in &self.pieces {
            match p {
                Piece::Text(t) => s.push_str(t),
                Piece::Frame { width } => s.push_str(&format!("{frame:0width$}")),
                Piece::Camera => s.push_str(camera),
                Piece::Structure => s.push_str(structure),
            }
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn expands_and_rejects() {
        let t = PathTemplate::parse("seeds/{camera}/{frame:06}.png").unwrap();
        assert_eq!(t.expand(42, "left", ""), "seeds/left/000042.png");
        let t = PathTemplate::parse("gt/hidden/{structure}/{camera}/f{frame}.png").unwrap();
        assert_eq!(
            t.expand(7, "right", "tumour_endo"),
            "gt/hidden/tumour_endo/right/f7.png"
        );
        assert_eq!(
            PathTemplate::parse("x/{frame:6}.png")
                .unwrap_err()
                .to_string(),
            "template 'x/{frame:6}.png': frame format '6' should look like 06"
        );
        assert_eq!(
            PathTemplate::parse("x/{frames}.png")
                .unwrap_err()
                .to_string(),
            "template 'x/{frames}.png' has an unknown placeholder '{frames}' (known: frame, camera, structure)"
        );
        assert_eq!(
            PathTemplate::parse("x/{frame.png").unwrap_err().to_string(),
            "template 'x/{frame.png' has an unclosed '{'"
        );
        assert!(!PathTemplate::parse("still.png").unwrap().uses_frame());
    }
}
