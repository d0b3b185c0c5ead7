//! Reading an ascii body: one record per non-blank line, every value checked against its
//! declared type.

use std::path::Path;

use super::binary::too_many;
use super::header::{show, Header, PropKind};
use super::scalar::Scalar;
use super::vertex::{Builder, RawVertex, VertexPlan};
use crate::error::{Error, Result};

struct Lines<'a> {
    bytes: &'a [u8],
    pos: usize,
    /// Number of the line at `pos` (1-based).
    line: usize,
}

impl<'a> Lines<'a> {
    /// The next non-blank line and its number.
    fn next_line(&mut self, path: &Path) -> Result<Option<(usize, &'a str)>> {
        while self.pos < self.bytes.len() {
            let rest = &self.bytes[self.pos..];
            let (raw, adv) = match rest.iter().position(|&b| b == b'\n') {
                Some(k) => (&rest[..k], k + 1),
                None => (rest, rest.len()),
            };
            let no = self.line;
            self.pos += adv;
            self.line += 1;
            let text = std::str::from_utf8(raw).map_err(|_| {
                Error::format(
                    path,
                    format!("line {no}"),
                    format!("not text: {}", show(raw)),
                )
            })?;
            if !text.trim_ascii().is_empty() {
                return Ok(Some((no, text)));
            }
        }
        Ok(None)
    }
}

pub(super) fn read_ascii(
    bytes: &[u8],
    path: &Path,
    header: &Header,
    vi: usize,
    plan: &VertexPlan,
    builder: &mut Builder,
) -> Result<()> {
    let mut lines = Lines {
        bytes,
        pos: header.body_start,
        line: header.body_line,
    };
    for (ei, el) in header.elements.iter().enumerate() {
        if el.props.is_empty() {
            continue;
        }
        // Each record is a line of at least one character and a newline (the last one may
        // lack its newline). This bounds what the count may make us reserve.
        let per = 2;
        let remaining = bytes.len() - lines.pos;
        if (el.count as u128) * (per as u128) > remaining as u128 + 1 {
            return Err(too_many(path, el, per, lines.pos, remaining));
        }
        let is_vertex = ei == vi;
        if is_vertex {
            builder.reserve(el.count as usize);
        }
        let mut v = RawVertex::default();
        for i in 0..el.count {
            // A long text body answers a stop request (SIGINT) within a fraction of a second.
            if i % 65_536 == 0 {
                crate::interrupt::check("reading the cloud")?;
            }
            let Some((no, text)) = lines.next_line(path)? else {
                return Err(Error::format(
                    path,
                    format!("line {}", lines.line),
                    format!(
                        "truncated body: the file ends after {i} of {} `{}` records",
                        el.count, el.name
                    ),
                ));
            };
            let mut toks = text.split_ascii_whitespace();
            let mut value = |s: Scalar, what: &str| -> Result<f64> {
                let tok = toks.next().ok_or_else(|| {
                    Error::format(
                        path,
                        format!("line {no}"),
                        format!(
                            "too few values for `{}` record {i}: {what} is missing",
                            el.name
                        ),
                    )
                })?;
                s.parse(tok).ok_or_else(|| {
                    Error::format(
                        path,
                        format!("line {no}"),
                        format!("`{tok}` is not a valid {} for {what}", s.name()),
                    )
                })
            };
            for (k, p) in el.props.iter().enumerate() {
                match p.kind {
                    PropKind::Scalar(s) => {
                        let x = value(s, &format!("property `{}`", p.name))?;
                        if is_vertex {
                            v.set(plan.roles[k], x);
                        }
                    }
                    PropKind::List { count, item } => {
                        let n = value(count, &format!("the length of list `{}`", p.name))?;
                        if n < 0.0 {
                            return Err(Error::format(
                                path,
                                format!("line {no}"),
                                format!("list `{}` has negative length {n}", p.name),
                            ));
                        }
                        for j in 0..n as u64 {
                            value(item, &format!("item {j} of list `{}`", p.name))?;
                        }
                    }
                }
            }
            if toks.next().is_some() {
                return Err(Error::format(
                    path,
                    format!("line {no}"),
                    format!(
                        "too many values for `{}` record {i} ({} properties declared)",
                        el.name,
                        el.props.len()
                    ),
                ));
            }
            if is_vertex {
                builder.push(&v);
            }
        }
    }
    Ok(())
}
