//! Path templates of scene.json: `{frame}`, `{frame:06}` (zero-padded width), `{camera}` and
//! `{structure}`; `{{` and `}}` stand for a literal brace (a folder named `br{x}`), as in
//! Python's and Rust's format strings. Parsed once, so a typo is reported at load time, not
//! mid-run.

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
        let mut text = String::new();
        let mut rest = source;
        while let Some(at) = rest.find(['{', '}']) {
            text.push_str(&rest[..at]);
            let tail = &rest[at..];
            // Doubled braces are literal ones; a lone `}` is kept as text, as it always was.
            if tail.starts_with("{{") || tail.starts_with("}}") {
                text.push_str(&tail[..1]);
                rest = &tail[2..];
                continue;
            }
            if let Some(after) = tail.strip_prefix('}') {
                text.push('}');
                rest = after;
                continue;
            }
            let close = tail.find('}').ok_or_else(|| TemplateError::Unclosed {
                template: source.to_string(),
            })?;
            let inner = &tail[1..close];
            let (name, spec) = inner.split_once(':').unwrap_or((inner, ""));
            let piece = match name {
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
            };
            if !text.is_empty() {
                pieces.push(Piece::Text(std::mem::take(&mut text)));
            }
            pieces.push(piece);
            rest = &tail[close + 1..];
        }
        text.push_str(rest);
        if !text.is_empty() {
            pieces.push(Piece::Text(text));
        }
        Ok(Self {
            source: source.to_string(),
            pieces,
        })
    }

    /// `text` as a template that expands to itself: its braces doubled.
    pub fn escape(text: &str) -> String {
        text.replace('{', "{{").replace('}', "}}")
    }

    /// What a template without placeholders stands for (its braces undoubled): a video's path.
    pub fn literal(&self) -> Option<String> {
        self.pieces
            .iter()
            .all(|p| matches!(p, Piece::Text(_)))
            .then(|| self.expand(0, "", ""))
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

    /// Doubled braces are literal ones, in text and around placeholders; `escape` makes any
    /// text a template of itself; `literal` undoes it where no placeholder is left.
    #[test]
    fn doubled_braces_are_literal() {
        let t = PathTemplate::parse("/v/br{{x}}/{camera}_{{{frame:03}}}}.png").unwrap();
        assert_eq!(t.expand(7, "left", ""), "/v/br{x}/left_{007}}.png");
        assert!(t.uses_frame());
        for text in ["/tmp/br{x}/a.mp4", "{frame}", "}{", "plain/left.mp4", ""] {
            let escaped = PathTemplate::escape(text);
            let t = PathTemplate::parse(&escaped).unwrap();
            assert!(!t.uses_frame(), "{escaped}");
            assert_eq!(t.literal().as_deref(), Some(text));
            assert_eq!(t.expand(3, "c", "s"), text);
        }
        let dir = PathTemplate::escape("/tmp/br{x}");
        let t = PathTemplate::parse(&format!("{dir}/L/{{frame:06}}.png")).unwrap();
        assert_eq!(t.expand(12, "", ""), "/tmp/br{x}/L/000012.png");
        assert_eq!(t.literal(), None);
        assert!(PathTemplate::parse("a/{x}").is_err());
        assert!(PathTemplate::parse("a/{frame").is_err());
    }

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
