//! OpenCV FileStorage YAML, the subset `cv::FileStorage` writes: an optional `%YAML:1.0` (or
//! `%YAML 1.0`) directive and `---`, then top-level `key: value` lines; a matrix is
//! `key: !!opencv-matrix` followed by indented `rows`, `cols`, `dt` and `data: [ … ]`, whose flow
//! sequence may span lines; `#` starts a comment. There is no YAML crate here, so this reader
//! does what that subset needs and no more: it cuts the text into top-level entries (a key, its
//! inline value, and the lines indented under it or inside its open brackets), then reads each
//! value as a scalar, a flow sequence or a matrix. A value it cannot read becomes
//! [`Node::Bad`] (an error only if the key is one the calibration needs), a nested mapping or
//! sequence [`Node::Other`]; unbalanced brackets and lines that are not `key: value` are errors
//! because they mean a truncated or foreign file. The writer prints numbers shortest
//! round-trip, which OpenCV reads as well as its own `%.16e`.

use std::fmt::Write as _;

use super::CalibError;
use super::opencv::{self, Entry, Matrix, Node, Storage};

/// A non-blank line, comment removed: its number (1-based), indentation and content.
struct Line<'a> {
    no: usize,
    indent: usize,
    text: &'a str,
}

/// A top-level (or nested) `key: value` with the lines that belong to it.
struct RawEntry<'t, 'l> {
    key: String,
    line: usize,
    inline: &'t str,
    rest: &'l [Line<'t>],
}

pub(crate) fn parse(text: &str) -> Result<Storage, CalibError> {
    let mut lines = Vec::new();
    let mut in_document = false;
    for (i, raw) in text.lines().enumerate() {
        let no = i + 1;
        let content = strip_comment(raw).trim_end();
        let body = content.trim_start();
        if body.is_empty() {
            continue;
        }
        let indent = content.len() - body.len();
        if indent == 0 && lines.is_empty() && !in_document && body.starts_with('%') {
            continue; // %YAML:1.0, %YAML 1.0, %TAG …
        }
        if indent == 0 && (body == "---" || body.starts_with("--- ")) {
            if lines.is_empty() && !in_document {
                in_document = true;
                continue;
            }
            break; // a second document: the first is the calibration
        }
        if indent == 0 && body == "..." {
            break;
        }
        lines.push(Line {
            no,
            indent,
            text: body,
        });
    }
    if lines.is_empty() {
        return Err(CalibError::Empty);
    }
    let entries = segment(&lines)?
        .into_iter()
        .map(|e| Entry {
            node: value(&e),
            key: e.key,
            line: e.line,
        })
        .collect();
    Storage::new(entries)
}

/// `raw` up to a `#` that starts a comment (at the start or after a blank, outside quotes).
fn strip_comment(raw: &str) -> &str {
    let mut quote = None;
    let mut prev_blank = true;
    for (i, c) in raw.char_indices() {
        match quote {
            Some(q) if c == q => quote = None,
            Some(_) => {}
            None if c == '"' || c == '\'' => quote = Some(c),
            None if c == '#' && prev_blank => return &raw[..i],
            None => {}
        }
        prev_blank = c == ' ' || c == '\t';
    }
    raw
}

/// How much `text` opens flow collections (`[`, `{`) minus how much it closes, outside quotes.
fn flow_delta(text: &str) -> i64 {
    let mut quote = None;
    let mut depth = 0;
    for c in text.chars() {
        match (quote, c) {
            (Some(q), c) if c == q => quote = None,
            (Some(_), _) => {}
            (None, '"' | '\'') => quote = Some(c),
            (None, '[' | '{') => depth += 1,
            (None, ']' | '}') => depth -= 1,
            _ => {}
        }
    }
    depth
}

/// Cuts `lines` (all at or below the first line's indentation) into `key: value` entries.
fn segment<'t, 'l>(lines: &'l [Line<'t>]) -> Result<Vec<RawEntry<'t, 'l>>, CalibError> {
    let Some(base) = lines.first().map(|l| l.indent) else {
        return Ok(Vec::new());
    };
    let mut out = Vec::new();
    let mut i = 0;
    while let Some(l) = lines.get(i) {
        if l.indent != base {
            return Err(CalibError::Syntax {
                line: l.no,
                problem: format!("indented {} columns, the keys above {base}", l.indent),
            });
        }
        let (key, inline) = split_key(l)?;
        let mut depth = flow_delta(inline);
        let mut j = i + 1;
        // A block sequence may sit at its key's indentation ("key:\n- a"): it belongs to the key.
        while let Some(next) = lines.get(j) {
            let item = next.text == "-" || next.text.starts_with("- ");
            if depth <= 0 && next.indent <= base && !(next.indent == base && item) {
                break;
            }
            depth += flow_delta(next.text);
            j += 1;
        }
        if depth != 0 {
            let problem = if depth > 0 {
                format!(
                    "a '[' or '{{' in the value of {key} is never closed (is the file truncated?)"
                )
            } else {
                format!("the value of {key} closes more brackets than it opens")
            };
            return Err(CalibError::Syntax {
                line: l.no,
                problem,
            });
        }
        out.push(RawEntry {
            key,
            line: l.no,
            inline,
            rest: &lines[i + 1..j],
        });
        i = j;
    }
    Ok(out)
}

/// The key and the inline value of `key: value` (the key may be quoted).
fn split_key<'t>(l: &Line<'t>) -> Result<(String, &'t str), CalibError> {
    let t = l.text;
    let fail = || CalibError::Syntax {
        line: l.no,
        problem: format!(
            "expected `key: value`, found {:?}",
            t.chars().take(40).collect::<String>()
        ),
    };
    let (key, after) = match t.chars().next() {
        Some(q @ ('"' | '\'')) => {
            let close = t[1..].find(q).ok_or_else(fail)? + 1;
            (&t[1..close], t[close + 1..].trim_start())
        }
        _ => {
            let colon = t
                .char_indices()
                .find(|&(i, c)| {
                    c == ':'
                        && t[i + 1..]
                            .chars()
                            .next()
                            .is_none_or(|n| n == ' ' || n == '\t')
                })
                .map(|(i, _)| i)
                .ok_or_else(fail)?;
            (t[..colon].trim_end(), &t[colon..])
        }
    };
    let rest = after.strip_prefix(':').ok_or_else(fail)?;
    if key.is_empty() || key.starts_with(['-', '[', '{', ']', '}', ',']) {
        return Err(fail());
    }
    Ok((key.to_string(), rest.trim()))
}

fn unquote(s: &str) -> &str {
    let s = s.trim();
    for q in ['"', '\''] {
        if let Some(inner) = s.strip_prefix(q).and_then(|r| r.strip_suffix(q)) {
            return inner;
        }
    }
    s
}

/// The items of a flow sequence `[ a, b, … ]` holding scalars.
fn flow_seq(text: &str) -> Result<Vec<String>, String> {
    let inner = text
        .trim()
        .strip_prefix('[')
        .and_then(|r| r.strip_suffix(']'))
        .ok_or_else(|| "a '[' sequence with text after its ']'".to_string())?;
    if inner.contains(['[', ']', '{', '}']) {
        return Err("a nested sequence or mapping, expected numbers".into());
    }
    let mut items: Vec<&str> = inner.split(',').map(str::trim).collect();
    if items.last() == Some(&"") {
        items.pop(); // "[ ]" and a trailing comma
    }
    if items.iter().any(|i| i.is_empty()) {
        return Err("an empty item between commas".into());
    }
    Ok(items.into_iter().map(|i| unquote(i).to_string()).collect())
}

/// The whole text of a value: its inline part and its continuation lines.
fn joined(inline: &str, rest: &[Line]) -> String {
    let mut s = inline.to_string();
    for l in rest {
        s.push(' ');
        s.push_str(l.text);
    }
    s
}

fn value(e: &RawEntry) -> Node {
    let inline = e.inline;
    let (tag, body) = match inline.strip_prefix('!') {
        Some(_) => inline.split_once([' ', '\t']).unwrap_or((inline, "")),
        None => ("", inline),
    };
    let body = body.trim();
    if tag.contains("opencv-nd-matrix") {
        return Node::Bad("n-dimensional matrices are not read".into());
    }
    if body.starts_with('[') {
        return flow_seq(&joined(body, e.rest)).map_or_else(Node::Bad, Node::Seq);
    }
    if body.starts_with('{') {
        return Node::Other("a flow mapping");
    }
    if body.is_empty() && !e.rest.is_empty() {
        if e.rest[0].text.starts_with('-') {
            return Node::Other("a sequence");
        }
        return match segment(e.rest) {
            Ok(fields) => matrix(&fields).unwrap_or(Node::Other("a mapping")),
            Err(err) => Node::Bad(err.to_string()),
        };
    }
    if tag.contains("opencv-matrix") {
        return Node::Bad("!!opencv-matrix without rows, cols, dt and data".into());
    }
    Node::Scalar(unquote(&joined(body, e.rest)).to_string())
}

/// A matrix from its fields, `None` if they are not those of a matrix (another mapping).
fn matrix(fields: &[RawEntry]) -> Option<Node> {
    let field = |name: &str| fields.iter().find(|f| f.key == name);
    let (rows, cols, data) = (field("rows")?, field("cols")?, field("data")?);
    let count = |f: &RawEntry| -> Result<usize, String> {
        let t = unquote(&joined(f.inline, f.rest)).to_string();
        t.parse::<usize>()
            .map_err(|_| format!("{} {t:?} is not a whole number", f.key))
    };
    let dt = field("dt").map_or("d".to_string(), |f| unquote(f.inline).to_string());
    let parsed = (|| -> Result<Matrix, String> {
        Ok(Matrix {
            rows: count(rows)?,
            cols: count(cols)?,
            dt,
            data: flow_seq(&joined(data.inline, data.rest))?,
        })
    })();
    Some(parsed.map_or_else(Node::Bad, Node::Matrix))
}

/// `cal` as FileStorage YAML.
pub(crate) fn write(cal: &super::Calibration) -> std::io::Result<String> {
    let mut s = String::from("%YAML:1.0\n---\n");
    if let Some((w, h)) = cal.image_size {
        let _ = writeln!(s, "imageSize: [ {w}, {h} ]");
    }
    for (key, rows, cols, data) in opencv::matrices(cal, "an OpenCV stereo file")? {
        let _ = write!(
            s,
            "{key}: !!opencv-matrix\n   rows: {rows}\n   cols: {cols}\n   dt: d\n   data: [ "
        );
        for (i, v) in data.iter().enumerate() {
            let sep = match i {
                0 => "",
                _ if i % 4 == 0 => ",\n       ",
                _ => ", ",
            };
            let _ = write!(s, "{sep}{v:?}");
        }
        s.push_str(" ]\n");
    }
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_the_subset() {
        let text = "%YAML 1.0\n---\n# comment\nnframes: 12 # trailing\nname: \"a # b\"\n\
                    M: !!opencv-matrix\n   rows: 1\n   cols: 3\n   dt: d\n   data: [ 0., 1.0e+03,\n       -4.3499e+00 ]\n\
                    nested:\n  a: 1\n  b: [ 1,\n 2 ]\nlist:\n- 1\n- 2\nsize: [ 640,\n  480 ]\n";
        let st = parse(text).unwrap();
        let want = Storage::new(vec![
            Entry {
                key: "nframes".into(),
                line: 4,
                node: Node::Scalar("12".into()),
            },
            Entry {
                key: "name".into(),
                line: 5,
                node: Node::Scalar("a # b".into()),
            },
            Entry {
                key: "M".into(),
                line: 6,
                node: Node::Matrix(Matrix {
                    rows: 1,
                    cols: 3,
                    dt: "d".into(),
                    data: vec!["0.".into(), "1.0e+03".into(), "-4.3499e+00".into()],
                }),
            },
            Entry {
                key: "nested".into(),
                line: 12,
                node: Node::Other("a mapping"),
            },
            Entry {
                key: "list".into(),
                line: 16,
                node: Node::Other("a sequence"),
            },
            Entry {
                key: "size".into(),
                line: 19,
                node: Node::Seq(vec!["640".into(), "480".into()]),
            },
        ])
        .unwrap();
        assert_eq!(st, want);
    }

    #[test]
    fn refuses_broken_structure() {
        let e = parse("K1: !!opencv-matrix\n   rows: 3\n   data: [ 1, 2,\n").unwrap_err();
        assert!(e.to_string().contains("never closed"), "{e}");
        let e = parse("a: 1\nthis is not yaml\n").unwrap_err();
        assert!(
            e.to_string().contains("line 2") && e.to_string().contains("key: value"),
            "{e}"
        );
        let e = parse("a: 1\na: 2\n").unwrap_err();
        assert!(
            matches!(
                e,
                CalibError::DuplicateKey {
                    first: 1,
                    second: 2,
                    ..
                }
            ),
            "{e}"
        );
        assert!(matches!(parse("%YAML:1.0\n---\n"), Err(CalibError::Empty)));
    }

    #[test]
    fn bad_matrix_fields_are_bad_nodes() {
        let st = parse("M: !!opencv-matrix\n  rows: three\n  cols: 1\n  data: [ 1 ]\n").unwrap();
        let want = Storage::new(vec![Entry {
            key: "M".into(),
            line: 1,
            node: Node::Bad("rows \"three\" is not a whole number".into()),
        }]);
        assert_eq!(Ok(st), want);
    }
}
