//! MAT v5: a 128-byte header, then data elements (tag: type and byte count, then data,
//! padded to 8 bytes; "small" elements of at most 4 bytes packed in the tag).

use super::*;

const MI_INT8: u32 = 1;
const MI_UINT8: u32 = 2;
const MI_INT16: u32 = 3;
const MI_UINT16: u32 = 4;
const MI_INT32: u32 = 5;
const MI_UINT32: u32 = 6;
const MI_SINGLE: u32 = 7;
const MI_DOUBLE: u32 = 9;
const MI_INT64: u32 = 12;
const MI_UINT64: u32 = 13;
const MI_MATRIX: u32 = 14;
const MI_COMPRESSED: u32 = 15;
const MI_UTF8: u32 = 16;

fn num_of(data_type: u32) -> Option<Num> {
    Some(match data_type {
        MI_INT8 => Num::I8,
        MI_UINT8 => Num::U8,
        MI_INT16 => Num::I16,
        MI_UINT16 => Num::U16,
        MI_INT32 => Num::I32,
        MI_UINT32 => Num::U32,
        MI_SINGLE => Num::F32,
        MI_DOUBLE => Num::F64,
        MI_INT64 => Num::I64,
        MI_UINT64 => Num::U64,
        _ => return None,
    })
}

fn class_name(class: u32) -> &'static str {
    match class {
        1 => "a cell array",
        2 => "a struct",
        3 => "an object",
        4 => "a character array (text)",
        5 => "a sparse matrix (convert it with `full(x)` first)",
        16 => "a function handle",
        17 => "a MATLAB object (e.g. a string, table or timeseries)",
        _ => "of an unknown class",
    }
}

struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
    big_endian: bool,
}

/// One data element.
struct Element<'a> {
    data_type: u32,
    data: &'a [u8],
    /// Offset of its tag in the buffer.
    at: usize,
}

impl<'a> Reader<'a> {
    fn u32_at(&self, at: usize) -> Option<u32> {
        let b: [u8; 4] = self.buf.get(at..at + 4)?.try_into().ok()?;
        Some(if self.big_endian {
            u32::from_be_bytes(b)
        } else {
            u32::from_le_bytes(b)
        })
    }

    fn done(&self) -> bool {
        self.pos >= self.buf.len()
    }

    /// The next element; `what` names it in errors. Compressed elements are not padded.
    fn element(&mut self, what: &str) -> Result<Element<'a>, ArrayFileError> {
        let at = self.pos;
        let first = self.u32_at(at).ok_or_else(|| {
            ArrayFileError::Truncated(format!("{what} at byte {at} has no complete tag"))
        })?;
        if first >> 16 != 0 {
            // Small element: type in the low half, byte count in the high half.
            let n = (first >> 16) as usize;
            let data = self.buf.get(at + 4..at + 8).ok_or_else(|| {
                ArrayFileError::Truncated(format!("{what} at byte {at} has no complete tag"))
            })?;
            if n > 4 {
                return Err(ArrayFileError::Malformed(format!(
                    "{what} at byte {at}: a small element of {n} bytes (at most 4)"
                )));
            }
            self.pos = at + 8;
            return Ok(Element {
                data_type: first & 0xffff,
                data: &data[..n],
                at,
            });
        }
        let n = self.u32_at(at + 4).ok_or_else(|| {
            ArrayFileError::Truncated(format!("{what} at byte {at} has no complete tag"))
        })? as usize;
        let start = at + 8;
        let end = start.checked_add(n).filter(|&e| e <= self.buf.len());
        let Some(end) = end else {
            return Err(ArrayFileError::Truncated(format!(
                "{what} at byte {at} announces {n} bytes but only {} follow",
                self.buf.len().saturating_sub(start)
            )));
        };
        let padded = if first == MI_COMPRESSED {
            end
        } else {
            end.div_ceil(8) * 8
        };
        self.pos = padded.min(self.buf.len());
        Ok(Element {
            data_type: first,
            data: &self.buf[start..end],
            at,
        })
    }
}

pub(super) fn parse(bytes: &[u8]) -> Result<Vec<Variable>, ArrayFileError> {
    if bytes.starts_with(b"MATLAB 7.3")
        || bytes.starts_with(HDF5_SIGNATURE)
        || bytes.get(512..520) == Some(HDF5_SIGNATURE)
    {
        return Err(ArrayFileError::MatV73);
    }
    if !bytes.starts_with(b"MATLAB 5.0 MAT-file") {
        return Err(ArrayFileError::UnknownFormat(
            "not a MAT-file of version 5 to 7: it does not start with the text \
             `MATLAB 5.0 MAT-file` (MATLAB v4 files are not read; save the variables with \
             `save('file.mat', 'u', 'y', '-v7')` or export them as CSV)"
                .into(),
        ));
    }
    if bytes.len() < 128 {
        return Err(ArrayFileError::Truncated(format!(
            "the MAT-file header has 128 bytes but the file has {}",
            bytes.len()
        )));
    }
    let big_endian = match &bytes[126..128] {
        b"IM" => false,
        b"MI" => true,
        other => {
            return Err(ArrayFileError::Malformed(format!(
                "the MAT-file header's byte-order mark is {other:?}, neither `IM` nor `MI`"
            )));
        }
    };
    let mut out = Vec::new();
    elements(&bytes[128..], big_endian, true, 128, &mut out)?;
    Ok(out)
}

/// Reads the variables of a sequence of top-level elements; `offset` is the position of
/// `buf` in the file (for messages).
fn elements(
    buf: &[u8],
    big_endian: bool,
    allow_compressed: bool,
    offset: usize,
    out: &mut Vec<Variable>,
) -> Result<(), ArrayFileError> {
    let mut r = Reader {
        buf,
        pos: 0,
        big_endian,
    };
    while !r.done() {
        // Trailing zero padding after the last element.
        if r.buf[r.pos..].iter().all(|&b| b == 0) {
            break;
        }
        let e = r.element("a variable")?;
        let at = offset + e.at;
        match e.data_type {
            MI_MATRIX => {
                if let Some(v) = matrix(e.data, big_endian, at)? {
                    out.push(v);
                }
            }
            MI_COMPRESSED if allow_compressed => {
                let inner = inflate(e.data, &|| format!("the compressed variable at byte {at}"))?;
                elements(&inner, big_endian, false, at, out).map_err(|err| match err {
                    ArrayFileError::Truncated(m) | ArrayFileError::Malformed(m) => {
                        ArrayFileError::Malformed(format!(
                            "in the compressed variable at byte {at}: {m}"
                        ))
                    }
                    other => other,
                })?;
            }
            t => {
                return Err(ArrayFileError::Malformed(format!(
                    "the element at byte {at} has data type {t}, not a variable (miMATRIX \
                     or miCOMPRESSED)"
                )));
            }
        }
    }
    Ok(())
}

/// One miMATRIX element: `None` for an empty one.
fn matrix(data: &[u8], big_endian: bool, at: usize) -> Result<Option<Variable>, ArrayFileError> {
    if data.is_empty() {
        return Ok(None);
    }
    let mut r = Reader {
        buf: data,
        pos: 0,
        big_endian,
    };
    let malformed =
        |m: String| ArrayFileError::Malformed(format!("the variable at byte {at}: {m}"));
    let flags = r.element("the array flags")?;
    if flags.data_type != MI_UINT32 || flags.data.len() < 8 {
        return Err(malformed(format!(
            "its array flags have type {} and {} bytes (expected miUINT32, 8 bytes)",
            flags.data_type,
            flags.data.len()
        )));
    }
    let word = |b: &[u8]| -> u32 {
        let b: [u8; 4] = [b[0], b[1], b[2], b[3]];
        if big_endian {
            u32::from_be_bytes(b)
        } else {
            u32::from_le_bytes(b)
        }
    };
    let f = word(&flags.data[..4]);
    let class = f & 0xff;
    let complex = f & 0x0800 != 0;
    let logical = f & 0x0200 != 0;
    let name_of = |e: &Element| -> Result<String, ArrayFileError> {
        if e.data_type != MI_INT8 && e.data_type != MI_UINT8 && e.data_type != MI_UTF8 {
            return Err(malformed(format!(
                "its name has data type {} (expected miINT8)",
                e.data_type
            )));
        }
        Ok(String::from_utf8_lossy(e.data).into_owned())
    };
    if class == 17 {
        // Objects (mxOPAQUE): the name follows the flags directly.
        let name = name_of(&r.element("the variable name")?)?;
        return Ok(Some(Variable {
            value: Err(ArrayFileError::Unsupported {
                name: name.clone(),
                what: class_name(17).into(),
            }),
            name,
        }));
    }
    let dims_el = r.element("the dimensions")?;
    if dims_el.data_type != MI_INT32 || dims_el.data.len() % 4 != 0 {
        return Err(malformed(format!(
            "its dimensions have type {} and {} bytes (expected miINT32)",
            dims_el.data_type,
            dims_el.data.len()
        )));
    }
    let dims: Vec<usize> = dims_el
        .data
        .chunks_exact(4)
        .map(|c| word(c) as i32)
        .map(|d| usize::try_from(d).unwrap_or(usize::MAX))
        .collect();
    if dims.len() < 2 || dims.contains(&usize::MAX) {
        return Err(malformed(format!(
            "invalid dimensions {:?}",
            dims_el
                .data
                .chunks_exact(4)
                .map(|c| word(c) as i32)
                .collect::<Vec<_>>()
        )));
    }
    let name = name_of(&r.element("the variable name")?)?;
    let unsupported = |what: &str| {
        Ok(Some(Variable {
            name: name.clone(),
            value: Err(ArrayFileError::Unsupported {
                name: name.clone(),
                what: what.to_string(),
            }),
        }))
    };
    if !(6..=15).contains(&class) {
        return unsupported(class_name(class));
    }
    if complex {
        return Ok(Some(Variable {
            name: name.clone(),
            value: Err(ArrayFileError::Complex { name }),
        }));
    }
    let (rows, cols) = match two_d(&name, &dims) {
        Ok(rc) => rc,
        Err(e) => {
            return Ok(Some(Variable {
                name,
                value: Err(e),
            }));
        }
    };
    let count = dims
        .iter()
        .try_fold(1usize, |p, &d| p.checked_mul(d))
        .filter(|&c| c <= data.len())
        .ok_or_else(|| {
            malformed(format!(
                "`{}` of size {} holds more values than the file has bytes",
                clip(&name),
                shape_text(&dims)
            ))
        })?;
    let real = r.element("the real part")?;
    let kind = num_of(real.data_type).ok_or_else(|| {
        malformed(format!(
            "`{}`: its values have data type {}, not a numeric type",
            clip(&name),
            real.data_type
        ))
    })?;
    let kind = if logical && kind == Num::U8 {
        Num::Bool
    } else {
        kind
    };
    let values = numbers(real.data, kind, big_endian, count).ok_or_else(|| {
        malformed(format!(
            "`{}` of size {} needs {count} values but its data hold {} bytes of {}-byte values",
            clip(&name),
            shape_text(&dims),
            real.data.len(),
            kind.size()
        ))
    })?;
    Ok(Some(Variable {
        name,
        value: Ok(Array {
            rows,
            cols,
            data: values,
        }),
    }))
}
