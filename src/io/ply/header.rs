//! The PLY header: its elements and properties, the body's encoding, the declared
//! organized layout and origin, and [`parse_header`], which reads and checks them line by line.

use std::path::Path;

use super::parse_origin;
use super::scalar::Scalar;
use crate::error::{Error, Result};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum PropKind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Clone, Debug)]
pub(super) struct Property {
    pub(super) name: String,
    pub(super) kind: PropKind,
}

#[derive(Clone, Debug)]
pub(super) struct Element {
    pub(super) name: String,
    pub(super) count: u64,
    pub(super) props: Vec<Property>,
    /// Header line that declared the element (1-based).
    pub(super) line: usize,
}

impl Element {
    /// Size in bytes of one binary record when it has no list property.
    pub(super) fn fixed_size(&self) -> Option<usize> {
        self.props.iter().try_fold(0usize, |acc, p| match p.kind {
            PropKind::Scalar(s) => Some(acc + s.size()),
            PropKind::List { .. } => None,
        })
    }

    /// Smallest possible binary record (lists empty).
    pub(super) fn min_binary_size(&self) -> usize {
        self.props
            .iter()
            .map(|p| match p.kind {
                PropKind::Scalar(s) => s.size(),
                PropKind::List { count, .. } => count.size(),
            })
            .sum()
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Encoding {
    Ascii,
    Binary { big_endian: bool },
}

#[derive(Clone, Copy, Debug)]
pub(super) struct Layout {
    pub(super) width: usize,
    pub(super) height: usize,
    pub(super) line: usize,
}

#[derive(Debug)]
pub(super) struct Header {
    pub(super) encoding: Encoding,
    pub(super) elements: Vec<Element>,
    /// Byte offset of the first body byte.
    pub(super) body_start: usize,
    /// Number of the first body line (1-based), for ascii error messages.
    pub(super) body_line: usize,
    pub(super) layout: Option<Layout>,
    /// `comment origin X Y Z`: the vertices are relative to this point of the map frame.
    pub(super) origin: Option<[f64; 3]>,
}

impl Header {
    pub(super) fn vertex_index(&self, path: &Path) -> Result<usize> {
        let mut found = None;
        for (i, e) in self.elements.iter().enumerate() {
            if e.name == "vertex" {
                if found.is_some() {
                    return Err(Error::format(
                        path,
                        format!("header line {}", e.line),
                        "a second `vertex` element",
                    ));
                }
                found = Some(i);
            }
        }
        found.ok_or_else(|| Error::format(path, "header", "no `vertex` element"))
    }
}

pub(super) fn show(bytes: &[u8]) -> String {
    let cut = &bytes[..bytes.len().min(24)];
    format!("{:?}", String::from_utf8_lossy(cut))
}

/// The line starting at `pos` (without its `\n`) and the position after it.
fn line_at(bytes: &[u8], pos: usize) -> (&[u8], usize) {
    let rest = &bytes[pos..];
    match rest.iter().position(|&b| b == b'\n') {
        Some(k) => (&rest[..k], pos + k + 1),
        None => (rest, bytes.len()),
    }
}

/// The length of line `l` without a trailing `\r`.
fn strip_cr(l: &[u8]) -> usize {
    l.len() - usize::from(l.last() == Some(&b'\r'))
}

/// Reads the header: the `ply` line, then keyword lines up to `end_header`, each checked
/// as it is read ([`HeaderParts::take`]). The header's line numbers are in every error.
pub(super) fn parse_header(bytes: &[u8], path: &Path) -> Result<Header> {
    if bytes.is_empty() {
        return Err(Error::format(path, "byte 0", "empty file (0 bytes)"));
    }
    let (first, mut pos) = line_at(bytes, 0);
    if &first[..strip_cr(first)] != b"ply" {
        return Err(Error::format(
            path,
            "line 1",
            format!(
                "not a PLY file: the first line must be `ply`, found {}",
                show(first)
            ),
        ));
    }

    let mut parts = HeaderParts::default();
    let mut line_no = 1;
    loop {
        if pos >= bytes.len() {
            return Err(Error::format(
                path,
                format!("header line {line_no}"),
                "malformed header: the file ends before `end_header`",
            ));
        }
        line_no += 1;
        let (raw, next) = line_at(bytes, pos);
        pos = next;
        let line = &raw[..strip_cr(raw)];
        if line.starts_with(b"comment") && std::str::from_utf8(line).is_err() {
            // A comment in a legacy encoding (Latin-1...) says nothing we read.
            continue;
        }
        let text = std::str::from_utf8(line).map_err(|_| {
            Error::format(
                path,
                format!("header line {line_no}"),
                format!(
                    "malformed header: line is not text ({}); is `end_header` missing?",
                    show(raw)
                ),
            )
        })?;
        let line = HeaderLine {
            path,
            no: line_no,
            text,
            toks: text.split_ascii_whitespace().collect(),
        };
        match line.toks.first().copied() {
            None => continue,
            Some("end_header") => {
                if line.toks.len() != 1 {
                    return Err(line.bad(format!("unexpected words after end_header: {text:?}")));
                }
                break;
            }
            Some(_) => parts.take(&line)?,
        }
    }
    let encoding = parts
        .encoding
        .ok_or_else(|| Error::format(path, "header", "malformed header: no `format` line"))?;
    Ok(Header {
        encoding,
        elements: parts.elements,
        body_start: pos,
        body_line: line_no + 1,
        layout: parts.layout,
        origin: parts.origin,
    })
}

/// One non-blank header line, split into words, with where it is for its errors.
struct HeaderLine<'a> {
    path: &'a Path,
    /// Line number in the file (1-based).
    no: usize,
    text: &'a str,
    toks: Vec<&'a str>,
}

impl HeaderLine<'_> {
    /// A `malformed header` error at this line.
    fn bad(&self, msg: String) -> Error {
        Error::format(
            self.path,
            format!("header line {}", self.no),
            format!("malformed header: {msg}"),
        )
    }
}

/// What the header lines read so far declared.
#[derive(Default)]
struct HeaderParts {
    encoding: Option<Encoding>,
    elements: Vec<Element>,
    layout: Option<Layout>,
    origin: Option<[f64; 3]>,
}

impl HeaderParts {
    /// Takes one keyword line (any but `end_header`).
    fn take(&mut self, line: &HeaderLine) -> Result<()> {
        match line.toks[0] {
            "format" => self.format(line),
            "comment" if line.toks.get(1) == Some(&"origin") => {
                let text = line.toks[2..].join(" ");
                self.origin = Some(parse_origin(&text).map_err(|m| line.bad(m))?);
                Ok(())
            }
            "comment" | "obj_info" => {
                self.comment(line);
                Ok(())
            }
            "element" => self.element(line),
            "property" => self.property(line),
            other => Err(line.bad(format!("unknown header keyword `{other}`"))),
        }
    }

    /// `format <ascii|binary_little_endian|binary_big_endian> 1.0`, once.
    fn format(&mut self, line: &HeaderLine) -> Result<()> {
        let (toks, text) = (&line.toks, line.text);
        if self.encoding.is_some() {
            return Err(line.bad("a second `format` line".into()));
        }
        if toks.len() != 3 {
            return Err(line.bad(format!(
                "expected `format <ascii|binary_little_endian|binary_big_endian> 1.0`, \
                 found {text:?}"
            )));
        }
        self.encoding = Some(match toks[1] {
            "ascii" => Encoding::Ascii,
            "binary_little_endian" => Encoding::Binary { big_endian: false },
            "binary_big_endian" => Encoding::Binary { big_endian: true },
            other => return Err(line.bad(format!("unknown format `{other}`"))),
        });
        if toks[2] != "1.0" {
            return Err(line.bad(format!("unsupported PLY version `{}`", toks[2])));
        }
        Ok(())
    }

    /// A comment or `obj_info` line: `width W height H` declares the organized layout;
    /// any other is ignored.
    fn comment(&mut self, line: &HeaderLine) {
        if let [_, "width", w, "height", h] = line.toks.as_slice() {
            if let (Ok(width), Ok(height)) = (w.parse(), h.parse()) {
                self.layout = Some(Layout {
                    width,
                    height,
                    line: line.no,
                });
            }
        }
    }

    /// `element <name> <count>`; one `vertex` element at most.
    fn element(&mut self, line: &HeaderLine) -> Result<()> {
        let (toks, text) = (&line.toks, line.text);
        if toks.len() != 3 {
            return Err(line.bad(format!("expected `element <name> <count>`, found {text:?}")));
        }
        let count: u64 = toks[2]
            .parse()
            .map_err(|_| line.bad(format!("bad element count `{}`", toks[2])))?;
        if self.elements.iter().any(|e| e.name == toks[1]) && toks[1] == "vertex" {
            return Err(line.bad("a second `vertex` element".into()));
        }
        self.elements.push(Element {
            name: toks[1].to_string(),
            count,
            props: Vec::new(),
            line: line.no,
        });
        Ok(())
    }

    /// `property <type> <name>` or `property list <count type> <item type> <name>`, of the
    /// last element; a name once per element.
    fn property(&mut self, line: &HeaderLine) -> Result<()> {
        let (toks, text) = (&line.toks, line.text);
        let Some(el) = self.elements.last_mut() else {
            return Err(line.bad("`property` before any `element`".into()));
        };
        let ty = |s: &str| {
            Scalar::from_name(s).ok_or_else(|| line.bad(format!("unknown property type `{s}`")))
        };
        let (kind, name) = match toks.as_slice() {
            [_, "list", c, i, name] => {
                let count = ty(c)?;
                if !count.is_integer() {
                    return Err(line.bad(format!(
                        "list count type must be an integer type, found `{c}`"
                    )));
                }
                (
                    PropKind::List {
                        count,
                        item: ty(i)?,
                    },
                    *name,
                )
            }
            [_, t, name] if *t != "list" => (PropKind::Scalar(ty(t)?), *name),
            _ => {
                return Err(line.bad(format!(
                    "expected `property <type> <name>` or `property list <count type> \
                     <item type> <name>`, found {text:?}"
                )))
            }
        };
        if el.props.iter().any(|p| p.name == name) {
            return Err(line.bad(format!(
                "property `{name}` appears twice in element `{}`",
                el.name
            )));
        }
        el.props.push(Property {
            name: name.to_string(),
            kind,
        });
        Ok(())
    }
}
