//! The lexical layer of the `.inp` reader: the deck as cards (keyword lines with their
//! parameters, data lines with their fields), and the field conversions that name the line
//! and the field on error.

use super::NodeRef;
use crate::error::GateError;

/// One logical line of the deck.
pub(super) enum Card {
    Keyword {
        line: usize,
        name: String,
        params: Vec<(String, String)>,
    },
    Data {
        line: usize,
        fields: Vec<String>,
    },
}

/// A parse error at `line` (1-based).
pub(super) fn err(line: usize, reason: impl Into<String>) -> GateError {
    GateError::InpParse {
        line,
        reason: reason.into(),
    }
}

/// Splits the text into cards: drops comments and blank lines, joins continued keyword lines.
pub(super) fn cards(text: &str) -> Result<Vec<Card>, GateError> {
    let mut out = Vec::new();
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l.trim()));
    while let Some((no, raw)) = lines.next() {
        if raw.is_empty() || raw.starts_with("**") {
            continue;
        }
        if let Some(rest) = raw.strip_prefix('*') {
            let mut full = rest.to_string();
            while full.trim_end().ends_with(',') {
                match lines.next() {
                    Some((_, next)) if !next.starts_with("**") => full.push_str(next),
                    _ => return Err(err(no, "keyword line ends with ',' but is not continued")),
                }
            }
            out.push(keyword_card(no, &full)?);
        } else {
            let mut fields: Vec<String> = raw.split(',').map(|f| f.trim().to_string()).collect();
            if fields.len() > 1 && fields.last().is_some_and(|f| f.is_empty()) {
                fields.pop();
            }
            out.push(Card::Data { line: no, fields });
        }
    }
    Ok(out)
}

fn keyword_card(line: usize, text: &str) -> Result<Card, GateError> {
    let mut parts = text.split(',');
    let name = parts
        .next()
        .unwrap_or("")
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
        .to_uppercase();
    if name.is_empty() {
        return Err(err(line, "empty keyword"));
    }
    let mut params = Vec::new();
    for p in parts.map(str::trim).filter(|p| !p.is_empty()) {
        let (k, v) = p.split_once('=').unwrap_or((p, ""));
        let key = k.split_whitespace().collect::<Vec<_>>().join(" ");
        params.push((key.to_uppercase(), v.trim().to_string()));
    }
    Ok(Card::Keyword { line, name, params })
}

pub(super) fn param<'a>(params: &'a [(String, String)], key: &str) -> Option<&'a str> {
    params
        .iter()
        .find(|(k, _)| k == key)
        .map(|(_, v)| v.as_str())
}

pub(super) fn required(
    params: &[(String, String)],
    key: &str,
    kw: &str,
    line: usize,
) -> Result<String, GateError> {
    match param(params, key) {
        Some(v) if !v.is_empty() => Ok(v.to_uppercase()),
        _ => Err(err(line, format!("*{kw} needs the parameter {key}="))),
    }
}

pub(super) fn number(field: &str, line: usize, what: &str) -> Result<f64, GateError> {
    let v: Result<f64, _> = field.replace(['d', 'D'], "e").parse();
    match v {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(err(
            line,
            format!("{what}: `{field}` is not a finite number"),
        )),
    }
}

pub(super) fn id(field: &str, line: usize, what: &str) -> Result<u64, GateError> {
    field.parse::<u64>().map_err(|_| {
        err(
            line,
            format!("{what}: `{field}` is not a non-negative integer"),
        )
    })
}

pub(super) fn dof(field: &str, line: usize) -> Result<usize, GateError> {
    match field.parse::<usize>() {
        Ok(d) if (1..=6).contains(&d) => Ok(d),
        _ => Err(err(
            line,
            format!("degree of freedom `{field}` must be 1..6"),
        )),
    }
}

pub(super) fn node_ref(field: &str) -> NodeRef {
    match field.parse::<u64>() {
        Ok(n) => NodeRef::Node(n),
        Err(_) => NodeRef::Set(field.to_uppercase()),
    }
}

pub(super) fn field<'a>(
    fields: &'a [String],
    i: usize,
    line: usize,
    what: &str,
) -> Result<&'a str, GateError> {
    fields
        .get(i)
        .map(String::as_str)
        .filter(|f| !f.is_empty())
        .ok_or_else(|| err(line, format!("missing {what} (field {})", i + 1)))
}
