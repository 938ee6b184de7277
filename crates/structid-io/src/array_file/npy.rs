//! NumPy `.npy`: magic, version, a Python-literal header dict (descr, fortran_order,
//! shape), then the raw data; `.npz`: a zip archive of them.

use super::*;

/// A Python literal of the header.
#[derive(Clone, Debug, PartialEq)]
enum Lit {
    Str(String),
    Int(u64),
    Bool(bool),
    None,
    Seq(Vec<Lit>),
    Dict(Vec<(Lit, Lit)>),
}

struct Parser<'a> {
    s: &'a [u8],
    pos: usize,
}

const MAX_DEPTH: usize = 16;

impl Parser<'_> {
    fn skip_ws(&mut self) {
        while self.pos < self.s.len() && self.s[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
    }

    fn peek(&mut self) -> Option<u8> {
        self.skip_ws();
        self.s.get(self.pos).copied()
    }

    fn err(&self, m: &str) -> String {
        format!("{m} at character {} of the header", self.pos)
    }

    fn value(&mut self, depth: usize) -> Result<Lit, String> {
        if depth > MAX_DEPTH {
            return Err(self.err("nesting too deep"));
        }
        match self.peek() {
            Some(q @ (b'\'' | b'"')) => {
                self.pos += 1;
                let start = self.pos;
                while self.pos < self.s.len() && self.s[self.pos] != q {
                    self.pos += 1;
                }
                if self.pos >= self.s.len() {
                    return Err(self.err("unterminated string"));
                }
                let text = String::from_utf8_lossy(&self.s[start..self.pos]).into_owned();
                self.pos += 1;
                Ok(Lit::Str(text))
            }
            Some(open @ (b'(' | b'[' | b'{')) => {
                self.pos += 1;
                let close = match open {
                    b'(' => b')',
                    b'[' => b']',
                    _ => b'}',
                };
                let mut items = Vec::new();
                let mut pairs = Vec::new();
                loop {
                    if self.peek() == Some(close) {
                        self.pos += 1;
                        break;
                    }
                    let v = self.value(depth + 1)?;
                    if open == b'{' {
                        if self.peek() != Some(b':') {
                            return Err(self.err("expected `:`"));
                        }
                        self.pos += 1;
                        let w = self.value(depth + 1)?;
                        pairs.push((v, w));
                    } else {
                        items.push(v);
                    }
                    match self.peek() {
                        Some(b',') => self.pos += 1,
                        Some(c) if c == close => {}
                        _ => return Err(self.err("expected `,` or a closing bracket")),
                    }
                }
                Ok(if open == b'{' {
                    Lit::Dict(pairs)
                } else {
                    Lit::Seq(items)
                })
            }
            Some(c) if c.is_ascii_alphanumeric() || c == b'-' => {
                let start = self.pos;
                while self.pos < self.s.len()
                    && (self.s[self.pos].is_ascii_alphanumeric() || self.s[self.pos] == b'-')
                {
                    self.pos += 1;
                }
                let word = std::str::from_utf8(&self.s[start..self.pos]).unwrap_or("");
                match word {
                    "True" => Ok(Lit::Bool(true)),
                    "False" => Ok(Lit::Bool(false)),
                    "None" => Ok(Lit::None),
                    w => w
                        .trim_end_matches('L')
                        .parse::<u64>()
                        .map(Lit::Int)
                        .map_err(|_| self.err(&format!("unexpected `{}`", clip(w)))),
                }
            }
            Some(_) => Err(self.err("unexpected character")),
            None => Err(self.err("unexpected end")),
        }
    }
}

/// A simple dtype: `None` for the reason it is not readable.
fn dtype(descr: &str) -> Result<(Num, bool), String> {
    let (order, rest) = match descr.as_bytes().first() {
        Some(b'<' | b'|' | b'=') => (false, &descr[1..]),
        Some(b'>') => (true, &descr[1..]),
        _ => (false, descr),
    };
    let kind = match rest {
        "f8" | "d" => Num::F64,
        "f4" | "f" => Num::F32,
        "i1" | "b" => Num::I8,
        "u1" | "B" => Num::U8,
        "b1" | "?" => Num::Bool,
        "i2" | "h" => Num::I16,
        "u2" | "H" => Num::U16,
        "i4" | "i" => Num::I32,
        "u4" | "I" => Num::U32,
        "i8" | "q" => Num::I64,
        "u8" | "Q" => Num::U64,
        _ => return Err(rest.to_string()),
    };
    Ok((kind, order))
}

fn size_of(descr: &str) -> Option<usize> {
    let digits: String = descr
        .chars()
        .skip_while(|c| !c.is_ascii_digit())
        .take_while(char::is_ascii_digit)
        .collect();
    digits.parse().ok()
}

/// What an unreadable dtype holds: `complex`, `text`, … .
fn what_dtype(descr: &str) -> String {
    let rest = descr.trim_start_matches(['<', '>', '|', '=']);
    match rest.chars().next() {
        Some('c') => "complex".into(),
        Some('O') => "Python objects (pickled; not read for safety)".into(),
        Some('U' | 'S' | 'a') => "text".into(),
        Some('M' | 'm') => "dates or time deltas".into(),
        _ => format!("dtype `{}`", clip(descr)),
    }
}

pub(super) fn parse(bytes: &[u8], name: &str) -> Result<Vec<Variable>, ArrayFileError> {
    let what = if name.is_empty() {
        String::new()
    } else {
        format!("member `{}`: ", clip(name))
    };
    let malformed = |m: String| ArrayFileError::Malformed(format!("{what}{m}"));
    let truncated = |m: String| ArrayFileError::Truncated(format!("{what}{m}"));
    if !bytes.starts_with(b"\x93NUMPY") {
        return Err(malformed(
            "not a NumPy .npy array (no `\\x93NUMPY` magic)".into(),
        ));
    }
    let major = *bytes
        .get(6)
        .ok_or_else(|| truncated("the .npy header is incomplete".into()))?;
    let (len, start) = match major {
        1 => (
            bytes
                .get(8..10)
                .map(|b| u16::from_le_bytes([b[0], b[1]]) as usize),
            10,
        ),
        2 | 3 => (
            bytes
                .get(8..12)
                .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize),
            12,
        ),
        v => {
            return Err(malformed(format!(
                ".npy format version {v} is not known (1 to 3 are)"
            )));
        }
    };
    let len = len.ok_or_else(|| truncated("the .npy header is incomplete".into()))?;
    let header = bytes.get(start..start + len).ok_or_else(|| {
        truncated(format!(
            "the .npy header announces {len} bytes but only {} follow",
            bytes.len().saturating_sub(start)
        ))
    })?;
    let data = &bytes[start + len..];
    let mut p = Parser { s: header, pos: 0 };
    let dict = match p
        .value(0)
        .map_err(|m| malformed(format!("bad .npy header: {m}")))?
    {
        Lit::Dict(d) => d,
        _ => return Err(malformed("the .npy header is not a dictionary".into())),
    };
    let key = |k: &str| {
        dict.iter()
            .find(|(n, _)| *n == Lit::Str(k.into()))
            .map(|(_, v)| v)
            .ok_or_else(|| malformed(format!("the .npy header has no `{k}`")))
    };
    let fortran = match key("fortran_order")? {
        Lit::Bool(b) => *b,
        _ => return Err(malformed("`fortran_order` is not True or False".into())),
    };
    let shape: Vec<usize> = match key("shape")? {
        Lit::Seq(items) => items
            .iter()
            .map(|i| match i {
                Lit::Int(n) => usize::try_from(*n).ok(),
                _ => None,
            })
            .collect::<Option<_>>()
            .ok_or_else(|| malformed("`shape` is not a tuple of sizes".into()))?,
        _ => return Err(malformed("`shape` is not a tuple".into())),
    };
    let count = shape
        .iter()
        .try_fold(1usize, |p, &d| p.checked_mul(d))
        .ok_or_else(|| malformed(format!("the shape {shape:?} overflows")))?;
    let var = |value| Variable {
        name: name.to_string(),
        value,
    };
    match key("descr")? {
        Lit::Str(descr) => {
            let (kind, big_endian) = match dtype(descr) {
                Ok(k) => k,
                Err(_) => {
                    let what = what_dtype(descr);
                    let e = if what == "complex" {
                        ArrayFileError::Complex {
                            name: name.to_string(),
                        }
                    } else {
                        ArrayFileError::Unsupported {
                            name: if name.is_empty() {
                                "the array".into()
                            } else {
                                name.into()
                            },
                            what: format!("an array of {what}"),
                        }
                    };
                    return Ok(vec![var(Err(e))]);
                }
            };
            let (rows, cols) = match two_d(name, &shape) {
                Ok(rc) => rc,
                Err(e) => return Ok(vec![var(Err(e))]),
            };
            if count
                .checked_mul(kind.size())
                .is_none_or(|n| n > data.len())
            {
                return Err(truncated(format!(
                    "the array of shape {shape:?} needs {count} values of {} bytes but {} \
                     bytes of data follow the header",
                    kind.size(),
                    data.len()
                )));
            }
            let values = numbers(data, kind, big_endian, count).unwrap_or_default();
            let data = if fortran || cols == 1 {
                values
            } else {
                let mut t = vec![0.0; count];
                for i in 0..rows {
                    for j in 0..cols {
                        t[j * rows + i] = values[i * cols + j];
                    }
                }
                t
            };
            Ok(vec![var(Ok(Array { rows, cols, data }))])
        }
        Lit::Seq(fields) => structured(fields, &shape, count, data, name, &malformed, &truncated),
        _ => Err(malformed(
            "`descr` is neither a dtype nor a list of fields".into(),
        )),
    }
}

/// A structured array: one variable per numeric field.
fn structured(
    fields: &[Lit],
    shape: &[usize],
    count: usize,
    data: &[u8],
    file: &str,
    malformed: &dyn Fn(String) -> ArrayFileError,
    truncated: &dyn Fn(String) -> ArrayFileError,
) -> Result<Vec<Variable>, ArrayFileError> {
    // (name, offset, dtype text, subarray shape given)
    let mut layout = Vec::new();
    let mut offset = 0usize;
    for f in fields {
        let Lit::Seq(parts) = f else {
            return Err(malformed("a field of `descr` is not a tuple".into()));
        };
        let (Some(Lit::Str(n)), Some(d)) = (parts.first(), parts.get(1)) else {
            return Err(malformed("a field of `descr` is not (name, dtype)".into()));
        };
        let Lit::Str(d) = d else {
            // A nested structure.
            return Err(malformed(format!(
                "field `{}` is a nested structure, which is not read",
                clip(n)
            )));
        };
        let size = size_of(d)
            .ok_or_else(|| malformed(format!("field `{}` has dtype `{}`", clip(n), clip(d))))?;
        let sub = parts.len() > 2;
        layout.push((n.clone(), offset, d.clone(), sub));
        offset = offset
            .checked_add(size)
            .ok_or_else(|| malformed("the record size overflows".into()))?;
    }
    let record = offset;
    let rows = match shape {
        [] => 1,
        [n] => *n,
        _ => {
            return Err(ArrayFileError::TooManyDims {
                name: if file.is_empty() {
                    "the array".into()
                } else {
                    file.into()
                },
                dims: shape.len(),
                shape: shape_text(shape),
            });
        }
    };
    if count.checked_mul(record).is_none_or(|n| n > data.len()) {
        return Err(truncated(format!(
            "{count} records of {record} bytes need more than the {} bytes of data",
            data.len()
        )));
    }
    let mut out = Vec::new();
    for (n, at, d, sub) in layout {
        if n.is_empty() {
            continue; // padding
        }
        let value = match dtype(&d) {
            _ if sub => Err(ArrayFileError::Unsupported {
                name: n.clone(),
                what: "a field with a sub-array shape".into(),
            }),
            Ok((kind, be)) => {
                let mut v = Vec::with_capacity(rows);
                for k in 0..rows {
                    let s = k * record + at;
                    let x = data
                        .get(s..s + kind.size())
                        .and_then(|b| numbers(b, kind, be, 1))
                        .and_then(|x| x.first().copied())
                        .ok_or_else(|| truncated("a record is incomplete".into()))?;
                    v.push(x);
                }
                Ok(Array {
                    rows,
                    cols: 1,
                    data: v,
                })
            }
            Err(_) if what_dtype(&d) == "complex" => {
                Err(ArrayFileError::Complex { name: n.clone() })
            }
            Err(_) => Err(ArrayFileError::Unsupported {
                name: n.clone(),
                what: format!("a field of {}", what_dtype(&d)),
            }),
        };
        out.push(Variable { name: n, value });
    }
    Ok(out)
}

pub(super) fn parse_npz(bytes: &[u8]) -> Result<Vec<Variable>, ArrayFileError> {
    let mut zip = zip::ZipArchive::new(std::io::Cursor::new(bytes)).map_err(|e| {
        ArrayFileError::Malformed(format!("not a readable .npz (zip) archive: {e}"))
    })?;
    let mut out = Vec::new();
    for i in 0..zip.len() {
        let mut member = zip.by_index(i).map_err(|e| {
            ArrayFileError::Malformed(format!("member {i} of the .npz archive: {e}"))
        })?;
        if member.is_dir() {
            continue;
        }
        let full = member
            .name()
            .map_err(|e| ArrayFileError::Malformed(format!("member {i} of the .npz archive: {e}")))?
            .to_string();
        let Some(name) = full.strip_suffix(".npy") else {
            continue;
        };
        let mut data = Vec::new();
        member
            .by_ref()
            .take(MAX_EXPANDED_BYTES + 1)
            .read_to_end(&mut data)
            .map_err(|e| ArrayFileError::Decompress {
                what: format!("member `{}` of the .npz archive", clip(&full)),
                message: e.to_string(),
            })?;
        if data.len() as u64 > MAX_EXPANDED_BYTES {
            return Err(ArrayFileError::Decompress {
                what: format!("member `{}` of the .npz archive", clip(&full)),
                message: format!("it expands to more than {} GiB", MAX_EXPANDED_BYTES >> 30),
            });
        }
        let mut vars = parse(&data, name)?;
        if vars.len() > 1 || vars.first().is_some_and(|v| v.name != name) {
            // A structured member: its fields are `member.field`.
            for v in &mut vars {
                v.name = format!("{name}.{}", v.name);
            }
        }
        out.extend(vars);
    }
    Ok(out)
}
