//! Reading a binary body: every size checked against the bytes present before anything is
//! reserved; fixed-size vertex records decoded straight from the bytes, others walked.

use std::path::Path;

use super::header::{Element, Header, PropKind};
use super::scalar::Scalar;
use super::vertex::{Builder, RawVertex, Role, VertexPlan};
use crate::error::{Error, Result};

pub(super) fn too_many(
    path: &Path,
    el: &Element,
    per: usize,
    pos: usize,
    remaining: usize,
) -> Error {
    let need = (el.count as u128) * (per as u128);
    Error::format(
        path,
        format!("byte {pos}"),
        format!(
            "header declares {} `{}` records of at least {per} bytes ({need} bytes) but only \
             {remaining} bytes remain in the file",
            el.count, el.name
        ),
    )
}

fn truncated(path: &Path, el: &Element, index: u64, pos: usize, len: usize) -> Error {
    Error::format(
        path,
        format!("byte {pos}"),
        format!(
            "truncated body: `{}` record {index} of {} runs past the end of the file ({len} bytes)",
            el.name, el.count
        ),
    )
}

/// Checks `count × min_size ≤ remaining` and returns the count as `usize`.
fn check_count(path: &Path, el: &Element, min: usize, pos: usize, len: usize) -> Result<usize> {
    let remaining = len - pos;
    match (el.count as u128).checked_mul(min as u128) {
        Some(need) if need <= remaining as u128 => {}
        _ => return Err(too_many(path, el, min, pos, remaining)),
    }
    if min == 0 {
        // Records without properties take no bytes; their count does not matter.
        return Ok(0);
    }
    Ok(el.count as usize)
}

/// Reads a list's length at `pos`.
fn list_len(
    bytes: &[u8],
    pos: usize,
    count: Scalar,
    big: bool,
    path: &Path,
    prop: &str,
) -> Result<Option<usize>> {
    let Some(b) = bytes.get(pos..pos + count.size()) else {
        return Ok(None);
    };
    let n = count.decode(b, big);
    if n < 0.0 {
        return Err(Error::format(
            path,
            format!("byte {pos}"),
            format!("list `{prop}` has negative length {n}"),
        ));
    }
    Ok(Some(n as usize))
}

/// Walks one variable-size binary record starting at `pos`, setting roled values into `v`.
/// Returns the position after the record, or `None` when the file ends inside it.
fn walk_record(
    bytes: &[u8],
    mut pos: usize,
    el: &Element,
    roles: Option<&[Role]>,
    big: bool,
    v: &mut RawVertex,
    path: &Path,
) -> Result<Option<usize>> {
    for (k, p) in el.props.iter().enumerate() {
        match p.kind {
            PropKind::Scalar(s) => {
                let Some(b) = bytes.get(pos..pos + s.size()) else {
                    return Ok(None);
                };
                if let Some(roles) = roles {
                    if roles[k] != Role::Skip {
                        v.set(roles[k], s.decode(b, big));
                    }
                }
                pos += s.size();
            }
            PropKind::List { count, item } => {
                let Some(n) = list_len(bytes, pos, count, big, path, &p.name)? else {
                    return Ok(None);
                };
                pos += count.size();
                let skip = n.checked_mul(item.size());
                match skip.and_then(|s| pos.checked_add(s)) {
                    Some(end) if end <= bytes.len() => pos = end,
                    _ => return Ok(None),
                }
            }
        }
    }
    Ok(Some(pos))
}

pub(super) fn read_binary(
    bytes: &[u8],
    path: &Path,
    header: &Header,
    vi: usize,
    plan: &VertexPlan,
    big: bool,
    builder: &mut Builder,
) -> Result<()> {
    let len = bytes.len();
    let mut pos = header.body_start;
    for (ei, el) in header.elements.iter().enumerate() {
        let count = check_count(path, el, el.min_binary_size(), pos, len)?;
        let is_vertex = ei == vi;
        if is_vertex {
            builder.reserve(count);
        }
        match el.fixed_size() {
            Some(stride) => {
                // check_count has proved count × stride ≤ remaining.
                let end = pos + count * stride;
                if is_vertex {
                    let fields: Vec<(usize, Scalar, Role)> = {
                        let mut off = 0;
                        let mut f = Vec::new();
                        for (p, &r) in el.props.iter().zip(&plan.roles) {
                            if let PropKind::Scalar(s) = p.kind {
                                if r != Role::Skip {
                                    f.push((off, s, r));
                                }
                                off += s.size();
                            }
                        }
                        f
                    };
                    builder.fill_fixed(&bytes[pos..end], stride, &fields, big);
                }
                pos = end;
            }
            None => {
                let roles = is_vertex.then_some(plan.roles.as_slice());
                let mut v = RawVertex::default();
                for i in 0..count as u64 {
                    match walk_record(bytes, pos, el, roles, big, &mut v, path)? {
                        Some(next) => pos = next,
                        None => return Err(truncated(path, el, i, pos, len)),
                    }
                    if is_vertex {
                        builder.push(&v);
                    }
                }
            }
        }
    }
    Ok(())
}
