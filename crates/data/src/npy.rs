//! NumPy's `.npy` files, as far as LLFF needs them: an array of little-endian `f64` in C order.
//!
//! The layout (NumPy's `format` module, versions 1.0 and 2.0): the magic `\x93NUMPY`, a major
//! and a minor version byte, the header's length (`u16` little-endian in 1.0, `u32` in 2.0),
//! the header, an ASCII Python dict literal such as
//! `{'descr': '<f8', 'fortran_order': False, 'shape': (20, 17), }` padded with spaces and a
//! newline, then the data. Anything else (another dtype, Fortran order, version 3.0's UTF-8
//! header) is refused with a [`DataError::BadArray`] naming what is wrong.

use std::path::Path;

use crate::error::DataError;

const MAGIC: &[u8] = b"\x93NUMPY";

/// An array read from an `.npy` file: its shape and its values in C order.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Array {
    pub shape: Vec<usize>,
    pub data: Vec<f64>,
}

/// Reads the `.npy` file `path`, which must hold `'<f8'` in C order. Errors:
/// [`DataError::BadArray`] for a wrong magic, version, header, dtype or order, or data longer
/// than the shape; [`DataError::Truncated`] for data shorter than the shape (checked before
/// anything is allocated for it).
pub(crate) fn read_f64(path: &Path) -> Result<Array, DataError> {
    let bytes = std::fs::read(path).map_err(|e| DataError::io(path, e))?;
    let bad = |what: &'static str, found: String, expected: &'static str| DataError::BadArray {
        path: path.to_path_buf(),
        what,
        found,
        expected,
    };
    if bytes.len() < 8 || &bytes[..6] != MAGIC {
        return Err(bad("the start", "not the .npy magic".into(), "\\x93NUMPY"));
    }
    let (length, start): (usize, usize) = match bytes[6] {
        1 if bytes.len() >= 10 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 if bytes.len() >= 12 => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
        1 | 2 => return Err(truncated(path, 8, "the header length", 4, bytes.len() - 8)),
        major => return Err(bad("the version", format!("{major}.{}", bytes[7]), "1.0 or 2.0")),
    };
    let end = start.saturating_add(length);
    if end > bytes.len() {
        return Err(truncated(path, start, "the header", length, bytes.len() - start));
    }
    let text = String::from_utf8_lossy(&bytes[start..end]);
    let header = Header::parse(&text).ok_or_else(|| {
        bad(
            "the header",
            one_line(&text),
            "a dict with 'descr', 'fortran_order' and 'shape'",
        )
    })?;
    if header.descr != "<f8" {
        return Err(bad(
            "the dtype",
            format!("'{}'", header.descr),
            "'<f8' (little-endian float64)",
        ));
    }
    if header.fortran_order {
        return Err(bad("fortran_order", "True".into(), "False (C order)"));
    }
    let count = header.shape.iter().try_fold(1usize, |n, &d| n.checked_mul(d));
    let needed = count.and_then(|n| n.checked_mul(8)).unwrap_or(usize::MAX);
    let data = &bytes[end..];
    if needed > data.len() {
        return Err(truncated(
            path,
            end,
            &format!("an array of shape {}", shape(&header.shape)),
            needed,
            data.len(),
        ));
    }
    if needed < data.len() {
        return Err(bad(
            "the data",
            format!("{} bytes for shape {}", data.len(), shape(&header.shape)),
            "8 bytes per element",
        ));
    }
    Ok(Array {
        shape: header.shape,
        data: data
            .chunks_exact(8)
            .map(|b| f64::from_le_bytes(b.try_into().expect("8 bytes")))
            .collect(),
    })
}

/// A shape as NumPy prints it: `(20, 17)`, `(5,)`, `()`.
pub(crate) fn shape(dims: &[usize]) -> String {
    match dims {
        [one] => format!("({one},)"),
        _ => format!(
            "({})",
            dims.iter().map(|d| d.to_string()).collect::<Vec<_>>().join(", ")
        ),
    }
}

fn truncated(path: &Path, offset: usize, what: &str, needed: usize, available: usize) -> DataError {
    DataError::Truncated {
        path: path.to_path_buf(),
        offset: offset as u64,
        what: what.to_string(),
        needed: needed as u64,
        available: available as u64,
    }
}

/// The header, shortened to one line for an error.
fn one_line(text: &str) -> String {
    let flat: String = text
        .trim()
        .chars()
        .map(|c| if c.is_control() { ' ' } else { c })
        .collect();
    match flat.char_indices().nth(80) {
        Some((i, _)) => format!("`{}...`", &flat[..i]),
        None => format!("`{flat}`"),
    }
}

/// The three keys of a header.
#[derive(Debug, PartialEq)]
struct Header {
    descr: String,
    fortran_order: bool,
    shape: Vec<usize>,
}

/// A value of a header's dict.
enum Value {
    Str(String),
    Bool(bool),
    Tuple(Vec<usize>),
}

impl Header {
    /// The header's dict literal, or `None` if it is not one with the three keys.
    fn parse(text: &str) -> Option<Header> {
        let mut p = Parser {
            s: text.as_bytes(),
            pos: 0,
        };
        p.expect(b'{')?;
        let (mut descr, mut fortran_order, mut shape) = (None, None, None);
        loop {
            if p.eat(b'}') {
                break;
            }
            let key = p.string()?;
            p.expect(b':')?;
            match (key.as_str(), p.value()?) {
                ("descr", Value::Str(s)) => descr = Some(s),
                ("fortran_order", Value::Bool(b)) => fortran_order = Some(b),
                ("shape", Value::Tuple(t)) => shape = Some(t),
                _ => return None,
            }
            if !p.eat(b',') {
                p.expect(b'}')?;
                break;
            }
        }
        Some(Header {
            descr: descr?,
            fortran_order: fortran_order?,
            shape: shape?,
        })
    }
}

struct Parser<'a> {
    s: &'a [u8],
    pos: usize,
}

impl Parser<'_> {
    fn skip_space(&mut self) {
        while self.s.get(self.pos).is_some_and(|c| c.is_ascii_whitespace()) {
            self.pos += 1;
        }
    }

    fn eat(&mut self, c: u8) -> bool {
        self.skip_space();
        let found = self.s.get(self.pos) == Some(&c);
        self.pos += usize::from(found);
        found
    }

    fn expect(&mut self, c: u8) -> Option<()> {
        self.eat(c).then_some(())
    }

    fn string(&mut self) -> Option<String> {
        self.skip_space();
        let quote = *self.s.get(self.pos).filter(|&&q| q == b'\'' || q == b'"')?;
        let len = self.s[self.pos + 1..].iter().position(|&c| c == quote)?;
        let out = String::from_utf8(self.s[self.pos + 1..self.pos + 1 + len].to_vec()).ok()?;
        self.pos += len + 2;
        Some(out)
    }

    fn word(&mut self, w: &str) -> bool {
        self.skip_space();
        let found = self.s[self.pos..].starts_with(w.as_bytes());
        self.pos += if found { w.len() } else { 0 };
        found
    }

    fn integer(&mut self) -> Option<usize> {
        self.skip_space();
        let len = self.s[self.pos..].iter().take_while(|c| c.is_ascii_digit()).count();
        let n = std::str::from_utf8(&self.s[self.pos..self.pos + len])
            .ok()?
            .parse()
            .ok()?;
        self.pos += len;
        // Python 2 wrote long integers with an `L`.
        self.pos += usize::from(self.s.get(self.pos) == Some(&b'L'));
        Some(n)
    }

    fn value(&mut self) -> Option<Value> {
        if self.word("True") {
            return Some(Value::Bool(true));
        }
        if self.word("False") {
            return Some(Value::Bool(false));
        }
        if self.eat(b'(') {
            let mut dims = Vec::new();
            while !self.eat(b')') {
                dims.push(self.integer()?);
                if !self.eat(b',') {
                    self.expect(b')')?;
                    break;
                }
            }
            return Some(Value::Tuple(dims));
        }
        self.string().map(Value::Str)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn headers_as_numpy_writes_them() {
        let h = Header::parse("{'descr': '<f8', 'fortran_order': False, 'shape': (20, 17), }          \n").unwrap();
        assert_eq!(
            h,
            Header {
                descr: "<f8".into(),
                fortran_order: false,
                shape: vec![20, 17]
            }
        );
        let h = Header::parse("{\"shape\": (5L,), \"fortran_order\": True, \"descr\": \"<f4\"}").unwrap();
        assert_eq!((h.shape, h.fortran_order, h.descr.as_str()), (vec![5], true, "<f4"));
        assert_eq!(Header::parse("{'descr': '<f8', 'shape': ()}"), None);
        assert_eq!(Header::parse("{'descr': '<f8', 'fortran_order': 0, 'shape': ()}"), None);
        assert_eq!(Header::parse("'descr': '<f8'"), None);
        assert_eq!(
            Header::parse("{'descr': '<f8', 'fortran_order': False, 'shape': ()}").map(|h| h.shape),
            Some(vec![])
        );
    }

    #[test]
    fn shapes_print_as_numpy_prints_them() {
        assert_eq!(shape(&[20, 17]), "(20, 17)");
        assert_eq!(shape(&[5]), "(5,)");
        assert_eq!(shape(&[]), "()");
    }
}
