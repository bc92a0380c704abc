//! OpenCV FileStorage XML, as `cv::FileStorage` writes it: `<?xml version="1.0"?>`, a root
//! `<opencv_storage>`, one element per key; a matrix is `<K1 type_id="opencv-matrix">` with
//! `<rows>`, `<cols>`, `<dt>` and `<data>` (whitespace-separated numbers) children, a sequence
//! such as `<imageSize>1280 1024</imageSize>` is whitespace-separated text. Read with quick-xml
//! 0.38 (events, not serde: the keys are element names another tool chooses). quick-xml 0.38
//! reports entity references as their own events rather than unescaping text; they cannot occur
//! in numbers, so they are kept verbatim and a number holding one is refused as not a number.
//! The element tree is built without recursion and at most [`MAX_DEPTH`] deep, so no input can
//! exhaust the stack; a file that ends before its elements close is refused as truncated.

use std::fmt::Write as _;

use quick_xml::Reader;
use quick_xml::events::{BytesStart, Event};

use super::CalibError;
use super::opencv::{self, Entry, Matrix, Node, Storage};

/// OpenCV's own files are 3 deep (storage, matrix, field).
const MAX_DEPTH: usize = 32;

#[derive(Default)]
struct Elem {
    name: String,
    type_id: Option<String>,
    line: usize,
    text: String,
    children: Vec<Elem>,
}

fn line_at(text: &str, pos: u64) -> usize {
    let pos = usize::try_from(pos).unwrap_or(usize::MAX).min(text.len());
    1 + text.as_bytes()[..pos]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
}

fn start(e: &BytesStart, text: &str, pos: u64) -> Elem {
    let type_id = e
        .try_get_attribute("type_id")
        .ok()
        .flatten()
        .map(|a| String::from_utf8_lossy(&a.value).into_owned());
    Elem {
        name: String::from_utf8_lossy(e.name().as_ref()).into_owned(),
        type_id,
        line: line_at(text, pos),
        ..Elem::default()
    }
}

/// The root element of `text`.
fn tree(text: &str) -> Result<Elem, CalibError> {
    let mut reader = Reader::from_str(text);
    let mut stack: Vec<Elem> = Vec::new();
    let mut root = None;
    loop {
        let pos = reader.buffer_position();
        let event = reader.read_event().map_err(|e| CalibError::Syntax {
            line: line_at(text, reader.error_position()),
            // quick-xml's syntax errors are all markup the input ends inside.
            problem: match e {
                quick_xml::Error::Syntax(_) => format!("{e} (is the file truncated?)"),
                _ => format!("not well-formed XML: {e}"),
            },
        })?;
        let syntax = |problem: String| CalibError::Syntax {
            line: line_at(text, pos),
            problem,
        };
        match event {
            Event::Start(e) => {
                if stack.len() >= MAX_DEPTH {
                    return Err(syntax(format!("elements nested deeper than {MAX_DEPTH}")));
                }
                stack.push(start(&e, text, pos));
            }
            Event::Empty(e) => {
                let elem = start(&e, text, pos);
                match stack.last_mut() {
                    Some(parent) => parent.children.push(elem),
                    None if root.is_none() => root = Some(elem),
                    None => return Err(syntax("a second root element".into())),
                }
            }
            Event::End(_) => {
                // quick-xml checks that the end tag matches the open one.
                let Some(elem) = stack.pop() else {
                    return Err(syntax("an end tag without a start tag".into()));
                };
                match stack.last_mut() {
                    Some(parent) => parent.children.push(elem),
                    None if root.is_none() => root = Some(elem),
                    None => return Err(syntax("a second root element".into())),
                }
            }
            Event::Text(t) => {
                let s = t.decode().map_err(|e| syntax(format!("text: {e}")))?;
                match stack.last_mut() {
                    Some(top) => top.text.push_str(&s),
                    None if s.trim().is_empty() => {}
                    None => return Err(syntax("text outside the root element".into())),
                }
            }
            Event::CData(t) => {
                if let Some(top) = stack.last_mut() {
                    top.text.push_str(&String::from_utf8_lossy(&t));
                }
            }
            Event::GeneralRef(r) => {
                if let Some(top) = stack.last_mut() {
                    let _ = write!(top.text, "&{};", String::from_utf8_lossy(&r));
                }
            }
            Event::Eof => break,
            Event::Comment(_) | Event::Decl(_) | Event::PI(_) | Event::DocType(_) => {}
        }
    }
    if let Some(open) = stack.last() {
        return Err(CalibError::Syntax {
            line: line_at(text, text.len() as u64),
            problem: format!(
                "the file ends inside <{}> (line {}): is it truncated?",
                open.name, open.line
            ),
        });
    }
    root.ok_or_else(|| CalibError::Syntax {
        line: 1,
        problem: "no XML element".into(),
    })
}

fn node(e: &Elem) -> Node {
    let tokens = || {
        e.text
            .split_whitespace()
            .map(str::to_string)
            .collect::<Vec<_>>()
    };
    if e.type_id
        .as_deref()
        .is_some_and(|t| t.contains("nd-matrix"))
    {
        return Node::Bad("n-dimensional matrices are not read".into());
    }
    if e.children.is_empty() {
        if e.type_id.as_deref() == Some("opencv-matrix") {
            return Node::Bad("opencv-matrix without rows, cols, dt and data".into());
        }
        let mut t = tokens();
        return match t.len() {
            0 => Node::Scalar(String::new()),
            1 => Node::Scalar(t.remove(0)),
            _ => Node::Seq(t),
        };
    }
    let field = |name: &str| e.children.iter().find(|c| c.name == name);
    let (Some(rows), Some(cols), Some(data)) = (field("rows"), field("cols"), field("data")) else {
        return Node::Other(if e.text.trim().is_empty() {
            "a mapping"
        } else {
            "mixed text and elements"
        });
    };
    let count = |f: &Elem| -> Result<usize, String> {
        let t = f.text.trim();
        t.parse::<usize>()
            .map_err(|_| format!("{} {t:?} is not a whole number", f.name))
    };
    let parsed = (|| -> Result<Matrix, String> {
        Ok(Matrix {
            rows: count(rows)?,
            cols: count(cols)?,
            dt: field("dt").map_or("d".into(), |f| f.text.trim().to_string()),
            data: data.text.split_whitespace().map(str::to_string).collect(),
        })
    })();
    parsed.map_or_else(Node::Bad, Node::Matrix)
}

pub(crate) fn parse(text: &str) -> Result<Storage, CalibError> {
    let root = tree(text)?;
    if root.name != "opencv_storage" {
        return Err(CalibError::Syntax {
            line: root.line,
            problem: format!(
                "the root element is <{}>, expected <opencv_storage>",
                root.name
            ),
        });
    }
    let entries = root
        .children
        .iter()
        .map(|c| Entry {
            key: c.name.clone(),
            line: c.line,
            node: node(c),
        })
        .collect();
    Storage::new(entries)
}

/// `cal` as FileStorage XML.
pub(crate) fn write(cal: &super::Calibration) -> std::io::Result<String> {
    let mut s = String::from("<?xml version=\"1.0\"?>\n<opencv_storage>\n");
    if let Some((w, h)) = cal.image_size {
        let _ = writeln!(s, "<imageSize>\n  {w} {h}</imageSize>");
    }
    for (key, rows, cols, data) in opencv::matrices(cal, "an OpenCV stereo file")? {
        let _ = write!(
            s,
            "<{key} type_id=\"opencv-matrix\">\n  <rows>{rows}</rows>\n  <cols>{cols}</cols>\n  <dt>d</dt>\n  <data>"
        );
        for (i, v) in data.iter().enumerate() {
            let sep = if i % 4 == 0 { "\n    " } else { " " };
            let _ = write!(s, "{sep}{v:?}");
        }
        let _ = writeln!(s, "</data></{key}>");
    }
    s.push_str("</opencv_storage>\n");
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_matrices_and_sequences() {
        let text = "<?xml version=\"1.0\"?>\n<opencv_storage>\n<nframes>12</nframes>\n\
                    <M type_id=\"opencv-matrix\">\n  <rows>1</rows>\n  <cols>2</cols>\n  <dt>d</dt>\n  <data>\n    0. 1.0e+03</data></M>\n\
                    <imageSize>\n  1280 1024</imageSize>\n<nested><a>1</a></nested>\n<empty/>\n</opencv_storage>\n";
        let st = parse(text).unwrap();
        let want = Storage::new(vec![
            Entry {
                key: "nframes".into(),
                line: 3,
                node: Node::Scalar("12".into()),
            },
            Entry {
                key: "M".into(),
                line: 4,
                node: Node::Matrix(Matrix {
                    rows: 1,
                    cols: 2,
                    dt: "d".into(),
                    data: vec!["0.".into(), "1.0e+03".into()],
                }),
            },
            Entry {
                key: "imageSize".into(),
                line: 10,
                node: Node::Seq(vec!["1280".into(), "1024".into()]),
            },
            Entry {
                key: "nested".into(),
                line: 12,
                node: Node::Other("a mapping"),
            },
            Entry {
                key: "empty".into(),
                line: 13,
                node: Node::Scalar(String::new()),
            },
        ])
        .unwrap();
        assert_eq!(st, want);
    }

    #[test]
    fn refuses_truncated_and_foreign_xml() {
        let e = parse("<?xml version=\"1.0\"?>\n<opencv_storage>\n<K1 type_id=\"opencv-matrix\">\n<rows>3</rows>").unwrap_err();
        assert!(
            e.to_string().contains("truncated") && e.to_string().contains("<K1>"),
            "{e}"
        );
        let e = parse("<svg><g/></svg>").unwrap_err();
        assert!(e.to_string().contains("<svg>"), "{e}");
        let e = parse("<opencv_storage><a>1</b></opencv_storage>").unwrap_err();
        assert!(e.to_string().contains("not well-formed"), "{e}");
        let deep = "<a>".repeat(100_000);
        assert!(parse(&deep).unwrap_err().to_string().contains("deeper"));
    }
}
